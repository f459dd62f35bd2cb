"""Named observations of ``urban_canyon_v0``: which entries mean what, in which units.

:func:`obs_layout` describes one agent's observation vector for a configuration: an ordered
mapping from a name to an :class:`ObsField` (index slice, physical units, scale, offset, bounds,
description), so that code can read ``obs[layout["next_waypoint"].slice]`` or decode it to
metres with ``layout["next_waypoint"].decode(obs)`` instead of working the indices out from the
``20 + 2A + 4K`` table of :mod:`coopnav_env.urban_canyon_v0`.

>>> from coopnav_env.envs import obs_layout
>>> layout = obs_layout()  # the default configuration: 52 entries
>>> layout["next_waypoint"].slice
slice(38, 40, None)
>>> layout["altitude"].units, layout["altitude"].offset, layout["altitude"].scale
('m', 5.0, 25.0)

Every stored entry is ``value = clip((quantity - offset) / scale, low, high)`` (float32), and
:meth:`ObsField.decode` inverts it: ``offset + value * scale`` (``value * scale`` when the
offset is 0). A clipped entry decodes to its bound: the quantity is at least that far out. The
fields are, in index order (``A = obs_sky_azimuths``, ``K = obs_neighbours``):

=========================  =====  ==========  ==============================================
name                       size   units       scale (offset)
=========================  =====  ==========  ==============================================
``position_to_goal``       3      m           ``L``, the larger side of the city extent
``velocity``               3      m/s         ``kinematics.max_speed_mps``
``sigma``                  3      m           ``obs_sigma_max_m``
``satellites``             1      1           1 (a ratio: received / above the cut-off)
``swarm_satellites``       1      1           1 (a ratio: with the UAVs in range)
``skyline``                A      deg         90
``neighbour_k``            3      m           ``relative_sensing.max_range_m``; k = 0..K-1
``neighbour_k_present``    1      flag        1 (the two alternate, slot by slot)
``cooperative_fix``        1      flag        1
``fresh_fix``              1      flag        1
``time_left``              1      steps       ``max_steps``
``next_waypoint``          2      m           ``obs_route_scale_m``
``next_leg``               2      m           ``obs_route_scale_m``
``remaining_route``        1      m           ``2 L``
``altitude``               1      m           band ``altitude_max_m - altitude_min_m``
                                              (offset ``altitude_min_m``)
``wall_distance``          A      m           ``obs_wall_scale_m``
``protection_level``       2      m           ``2 alert_limit_m``; only with
                                              ``obs_protection_level`` (HPL, VPL)
``satellites_received_     A      1           4 (satellites tracked per azimuth sector); only
sector``                                      with ``obs_satellite_sectors``
``satellites_blocked_      A      1           4 (satellites above the cut-off not tracked,
sector``                                      per azimuth sector); only with
                                              ``obs_satellite_sectors``
``true_error``             3      m           ``obs_sigma_max_m`` (the true error of the
                                              estimate used, E, N, U; privileged, a
                                              diagnostic); only with ``obs_true_error``
``agent_index``            N      1           1 (one-hot index of the UAV in
                                              ``possible_agents``); only with
                                              ``obs_agent_index``
=========================  =====  ==========  ==============================================

The sector of skyline azimuth ``360 a / A`` is centred on it and ``360 / A`` degrees wide
(see :meth:`coopnav_env.envs.task.UrbanCanyonTask.satellite_sectors`); a count of 4 or more
reads 1.

``L`` depends only on the configuration (the grid's extent is ``n * block + (n + 1) * street``
whatever the buildings; the canyon is fixed), so it is known before any episode. The layout
is checked against the environment's observations in ``tests/envs/test_observation_layout.py``.
"""

from __future__ import annotations

import builtins
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from coopnav_env.envs.config import UrbanCanyonConfig, make_config

__all__ = ["ObsField", "ObsLayout", "city_scale_m", "obs_layout"]

_ENU = ("E", "N", "U")


@dataclass(frozen=True)
class ObsField:
    """One named block of consecutive observation entries.

    Attributes
    ----------
    name : str
        Key in :class:`ObsLayout` (e.g. ``"next_waypoint"``, ``"neighbour_2_present"``).
    start, stop : int
        The entries ``obs[start:stop]`` (see :attr:`slice`).
    units : str
        Units of the decoded quantity: ``"m"``, ``"m/s"``, ``"deg"``, ``"steps"``, ``"1"``
        (a dimensionless ratio) or ``"flag"`` (0 or 1).
    scale : float
        The quantity (minus :attr:`offset`) that reads 1, in :attr:`units`.
    offset : float
        The quantity that reads 0 (only the altitude has one).
    low, high : float
        Bounds of every stored entry (those of the observation space).
    description : str
        What the entries measure.
    scale_name : str
        Where the scale comes from (a configuration field, ``"L"`` for the city size, ...).
    components : tuple of str
        One label per entry (``"E"``, ``"N"``, ``"U"``, an azimuth such as ``"45 deg"``, ...).
    """

    name: str
    start: int
    stop: int
    units: str
    scale: float
    offset: float
    low: float
    high: float
    description: str
    scale_name: str
    components: tuple[str, ...]

    @property
    def slice(self) -> builtins.slice:
        """``slice(start, stop)``: ``obs[..., field.slice]`` are the field's entries."""
        return builtins.slice(self.start, self.stop)

    @property
    def size(self) -> int:
        """Number of entries."""
        return self.stop - self.start

    def decode(self, obs: Any) -> np.ndarray:
        """The field's entries of ``obs`` (last axis) in :attr:`units`, float64.

        ``offset + value * scale``; with a zero offset just ``value * scale``, so the result
        is the same float64 product code would write by hand. Clipped entries decode to the
        bound (e.g. a sigma above ``obs_sigma_max_m`` decodes to ``obs_sigma_max_m``).
        """
        value = np.asarray(obs, dtype=np.float64)[..., self.start : self.stop] * self.scale
        return self.offset + value if self.offset != 0.0 else value


class ObsLayout(Mapping[str, ObsField]):
    """The observation layout of one configuration: an ordered mapping name -> :class:`ObsField`.

    Iteration follows the index order; the fields cover ``range(dim)`` exactly once.

    Attributes
    ----------
    dim : int
        Length of the observation vector (``config.obs_dim``).
    city_scale_m : float
        ``L``, the larger side of the city extent [m], the scale of the position entries.
    config : UrbanCanyonConfig
        The configuration described.
    """

    def __init__(self, fields: list[ObsField], config: UrbanCanyonConfig, city_scale: float):
        self._fields = {f.name: f for f in fields}
        self.dim = int(config.obs_dim)
        self.city_scale_m = float(city_scale)
        self.config = config

    def __getitem__(self, name: str) -> ObsField:
        try:
            return self._fields[name]
        except KeyError:
            raise KeyError(
                f"no observation field {name!r}; fields: {', '.join(self._fields)}"
            ) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._fields)

    def __len__(self) -> int:
        return len(self._fields)

    def __repr__(self) -> str:
        rows = [f"ObsLayout(dim={self.dim}, city_scale_m={self.city_scale_m:g})"]
        width = max(22, *(len(name) for name in self))
        for f in self.values():
            offset = f" + {f.offset:g}" if f.offset else ""
            where = f"{f.start:>3}:{f.stop:<3}"
            rows.append(f"  {where} {f.name:<{width}} {f.units:<5} x {f.scale:g}{offset}")
        return "\n".join(rows)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-entry bounds ``(low, high)``, float32, those of the observation space."""
        low = np.empty(self.dim, dtype=np.float32)
        high = np.empty(self.dim, dtype=np.float32)
        for f in self.values():
            low[f.slice], high[f.slice] = f.low, f.high
        return low, high

    def decode(self, obs: Any) -> dict[str, np.ndarray]:
        """Every field of ``obs`` (one observation, or a stack along the first axes) decoded."""
        return {name: f.decode(obs) for name, f in self.items()}

    def neighbour_present_indices(self) -> np.ndarray:
        """Indices of the ``K`` neighbour-present flags, slot 0 (nearest) first."""
        k = self.config.obs_neighbours
        return np.array([self[f"neighbour_{i}_present"].start for i in range(k)], dtype=np.intp)


def city_scale_m(config: UrbanCanyonConfig) -> float:
    """``L``: the larger side of the city extent of ``config`` [m] (any episode's city).

    The extent does not depend on the random buildings (a grid city spans ``n * block +
    (n + 1) * street`` on each axis, the canyon is fixed), so one throw-away city gives it.
    """
    from coopnav_env.sim.scenario import make_city

    x0, x1, y0, y1 = make_city(config, np.random.default_rng(0)).extent_m
    return float(max(x1 - x0, y1 - y0))


def obs_layout(config: Any = None, **overrides: Any) -> ObsLayout:
    """The named layout of one agent's observation for a configuration.

    Parameters
    ----------
    config : UrbanCanyonConfig, an urban_canyon_v0 environment, or None
        The configuration (an environment's ``config`` is taken, also through wrappers with
        ``unwrapped``); None: ``UrbanCanyonConfig()``.
    **overrides
        :class:`~coopnav_env.envs.UrbanCanyonConfig` fields applied on top (as for
        ``urban_canyon_v0.parallel_env``).

    Returns
    -------
    ObsLayout
        See the module docstring for the fields.

    Raises
    ------
    ValueError
        ``config`` is neither a configuration nor an environment with one, or an override is
        unknown or invalid.
    """
    if config is not None and not isinstance(config, UrbanCanyonConfig):
        inner = getattr(getattr(config, "unwrapped", config), "config", None)
        if not isinstance(inner, UrbanCanyonConfig):
            raise ValueError(
                "obs_layout needs an UrbanCanyonConfig, an urban_canyon_v0 environment or None, "
                f"got {type(config).__name__}"
            )
        config = inner
    cfg = make_config(config, **overrides)
    big = city_scale_m(cfg)
    kin = cfg.kinematics
    a, k = cfg.obs_sky_azimuths, cfg.obs_neighbours
    az = tuple(f"{360.0 * i / a:g} deg" for i in range(a))
    fields: list[ObsField] = []

    def add(
        name: str,
        size: int,
        units: str,
        scale: float,
        low: float,
        description: str,
        scale_name: str,
        components: tuple[str, ...] | None = None,
        offset: float = 0.0,
    ) -> None:
        start = fields[-1].stop if fields else 0
        labels = ("",) * size if components is None else tuple(components)
        assert len(labels) == size, name
        fields.append(
            ObsField(
                name=name,
                start=start,
                stop=start + size,
                units=units,
                scale=float(scale),
                offset=float(offset),
                low=float(low),
                high=1.0,
                description=description,
                scale_name=scale_name,
                components=labels,
            )
        )

    add("position_to_goal", 3, "m", big, -1, "estimated position minus the goal centre", "L", _ENU)
    add("velocity", 3, "m/s", kin.max_speed_mps, -1, "velocity", "kinematics.max_speed_mps", _ENU)
    add(
        "sigma",
        3,
        "m",
        cfg.obs_sigma_max_m,
        0,
        "predicted sigma of the estimate per axis (H_p of Eq. 19-23 for a cooperative fix)",
        "obs_sigma_max_m",
        _ENU,
    )
    add("satellites", 1, "1", 1, 0, "satellites received / satellites above the cut-off", "1")
    add(
        "swarm_satellites",
        1,
        "1",
        1,
        0,
        "distinct satellites of the UAV and the UAVs in range / satellites above the cut-off",
        "1",
    )
    add("skyline", a, "deg", 90, 0, "skyline elevation, azimuth clockwise from North", "90", az)
    for i in range(k):
        add(
            f"neighbour_{i}",
            3,
            "m",
            cfg.relative_sensing.max_range_m,
            -1,
            f"measured position of the neighbour in slot {i} (nearest first) relative to the UAV",
            "relative_sensing.max_range_m",
            _ENU,
        )
        add(f"neighbour_{i}_present", 1, "flag", 1, 0, f"slot {i} holds a neighbour", "1")
    add("cooperative_fix", 1, "flag", 1, 0, "the estimate is a cooperative fix", "1")
    add("fresh_fix", 1, "flag", 1, 0, "the estimate is a fix, not dead reckoning", "1")
    add("time_left", 1, "steps", cfg.max_steps, 0, "steps left in the episode", "max_steps")
    route_scale = cfg.obs_route_scale_m
    add(
        "next_waypoint",
        2,
        "m",
        route_scale,
        -1,
        "next route waypoint minus the estimated position",
        "obs_route_scale_m",
        _ENU[:2],
    )
    add(
        "next_leg",
        2,
        "m",
        route_scale,
        -1,
        "the route leg after the next waypoint (0 when that waypoint is the goal)",
        "obs_route_scale_m",
        _ENU[:2],
    )
    add("remaining_route", 1, "m", 2.0 * big, 0, "street route left from the estimate", "2 L")
    add(
        "altitude",
        1,
        "m",
        kin.altitude_max_m - kin.altitude_min_m,
        0,
        "estimated altitude (offset: the bottom of the altitude band)",
        "kinematics.altitude_max_m - kinematics.altitude_min_m",
        offset=kin.altitude_min_m,
    )
    add(
        "wall_distance",
        a,
        "m",
        cfg.obs_wall_scale_m,
        0,
        "horizontal distance to the nearest taller building, azimuth clockwise from North",
        "obs_wall_scale_m",
        az,
    )
    if cfg.obs_protection_level:
        add(
            "protection_level",
            2,
            "m",
            2.0 * cfg.alert_limit_m,
            0,
            "horizontal and vertical protection level of the estimate used (1: none)",
            "2 alert_limit_m",
            ("H", "V"),
        )
    if cfg.obs_satellite_sectors:
        add(
            "satellites_received_sector",
            a,
            "1",
            4,
            0,
            "satellites tracked whose azimuth is in the sector (clockwise from North)",
            "4",
            az,
        )
        add(
            "satellites_blocked_sector",
            a,
            "1",
            4,
            0,
            "satellites above the cut-off not tracked whose azimuth is in the sector",
            "4",
            az,
        )
    if cfg.obs_true_error:
        add(
            "true_error",
            3,
            "m",
            cfg.obs_sigma_max_m,
            -1,
            "true position error of the estimate used (privileged: a diagnostic)",
            "obs_sigma_max_m",
            _ENU,
        )
    if cfg.obs_agent_index:
        add(
            "agent_index",
            cfg.n_uavs,
            "1",
            1,
            0,
            "one-hot index of the UAV in possible_agents",
            "1",
            tuple(str(i) for i in range(cfg.n_uavs)),
        )
    if fields[-1].stop != cfg.obs_dim:  # pragma: no cover - guarded by the tests
        raise AssertionError(f"layout covers {fields[-1].stop} entries, obs_dim {cfg.obs_dim}")
    return ObsLayout(fields, cfg, big)
