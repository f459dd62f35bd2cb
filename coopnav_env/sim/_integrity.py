"""Integrity monitoring in the urban world (``ScenarioConfig.integrity``): the glue between
:class:`~coopnav_env.sim.scenario.UrbanWorld` and :mod:`coopnav_env.nav.integrity`.

With ``integrity="raim"`` or ``"fde"`` every epoch's standalone and cooperative fixes go
through the residual test (and, for ``"fde"``, exclusion) before the estimate selection; a
fix whose fault is not cleared has ``NavStatus.FAULT_DETECTED`` and the UAV falls back to its
next source. The default (fused) path runs it inside its one compiled call
(:func:`coopnav_env.sim._kernels.epoch_navigation` with ``fde``, the stage
:func:`coopnav_env.sim._integrity_kernels.epoch_fde`); the modular path
(:meth:`UrbanWorld._navigate`, for the paper's covariance or satellites not grouped by
constellation) calls the public :func:`~coopnav_env.nav.fde_standalone` and
:func:`~coopnav_env.nav.fde_cooperative`, which run the same kernels on the same arguments.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from coopnav_env.nav import RelativePositions
from coopnav_env.nav.integrity import (
    fde_cooperative,
    fde_standalone,
    protection_factors,
    threshold_tables,
)
from coopnav_env.sim._integrity_kernels import used_integrity

__all__ = ["EpochIntegrity", "fused_arguments", "modular_fde", "unpack"]

#: The integrity figures of the estimate each UAV uses, in this order (``Epoch`` fields):
#: ``hpl_m, vpl_m, integrity_status, fault_detected, fde_excluded``.
EpochIntegrity = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _max_exclusions(config: Any) -> int | None:
    """Exclusions per fix: none for ``"raim"`` (detection only), unlimited for ``"fde"``."""
    return 0 if config.integrity == "raim" else None


def fused_arguments(config: Any, received: np.ndarray) -> tuple:
    """The ``fde`` argument of ``epoch_navigation``: thresholds and non-centralities
    (tables covering every degree of freedom this epoch can have: one per possible
    measurement, entry d computed alone, so a larger table has the same entries), the
    fault-free factors, the exclusions allowed per fix and the one-sided identification flag
    (cached per setting, grown when an epoch could have more measurements than they cover;
    the last config's entry is kept beside the cache, found by identity: this runs every
    epoch)."""
    last_config, last_hit = _LAST
    if config is last_config and last_hit[0].shape[0] > received.size:
        return last_hit
    key = (config.integrity, config.integrity_p_fa, config.integrity_risk)
    key += (config.integrity_fault_sign,)
    hit = _FUSED.get(key)
    if hit is None or hit[0].shape[0] <= received.size:  # grown to cover every possible row
        size = max(received.size, 1)
        thr, lam = threshold_tables(config.integrity_p_fa, config.integrity_risk, size)
        k_h, k_v = protection_factors(config.integrity_risk)
        max_excl = _max_exclusions(config)
        max_excl = (1 << 30) if max_excl is None else max_excl
        hit = (thr, lam, k_h, k_v, max_excl, config.integrity_fault_sign == "positive")
        _FUSED[key] = hit
    _LAST[:] = [config, hit]
    return hit


_FUSED: dict[tuple, tuple] = {}
_LAST: list = [None, (np.empty(0),)]  # (config, its entry of _FUSED)


def modular_fde(world: Any, obs, sa, co, rel_b, var_b, avail_b, centroid):
    """FDE of an epoch's standalone and cooperative solutions by the public functions.

    ``rel_b, var_b, avail_b``: the relative rows the cooperative solve used
    (``UrbanWorld._relative_rows``). Returns the solutions after FDE and a function of the
    selection's ``source`` giving the :data:`EpochIntegrity` of the estimates used.
    """
    cfg = world.config
    kw = dict(
        p_fa=cfg.integrity_p_fa,
        integrity_risk=cfg.integrity_risk,
        max_exclusions=_max_exclusions(cfg),
        max_iter=cfg.nav_max_iter,
        enu_rotation=world.rot_enu,
        fault_sign=cfg.integrity_fault_sign,
    )
    sa, sa_r = fde_standalone(obs, sa, **kw)
    n = obs.n_rx
    if isinstance(centroid, str):
        rel_ecef, var, avail = rel_b, var_b, avail_b
    else:  # only the shared centroid's row
        rel_ecef = np.zeros((n, n, 3))
        var = np.zeros((n, n))
        avail = np.zeros((n, n), dtype=bool)
        rel_ecef[centroid], var[centroid], avail[centroid] = rel_b, var_b, avail_b
    rel = RelativePositions._trusted(rel_ecef, var[:, :, None, None] * np.eye(3), avail)
    co, co_r = fde_cooperative(obs, rel, co, transfer=cfg.transfer, centroid=centroid, **kw)

    def used(source: np.ndarray) -> EpochIntegrity:
        # the kernel's records (_integrity_kernels.FixIntegrity) as plain tuples
        return unpack(
            used_integrity(
                np.ascontiguousarray(source, dtype=np.int64),
                (co_r.status, co_r.fault_detected, co_r.n_excluded, co_r.hpl_m, co_r.vpl_m),
                (sa_r.status, sa_r.fault_detected, sa_r.n_excluded, sa_r.hpl_m, sa_r.vpl_m),
            )
        )

    return sa, co, used


def unpack(packed: np.ndarray) -> EpochIntegrity:
    """The :data:`EpochIntegrity` of :func:`~coopnav_env.sim._integrity_kernels.used_integrity`'s
    packed ``(5, N)`` array."""
    return (
        packed[0],
        packed[1],
        packed[2].astype(np.int64),
        packed[3] != 0.0,
        packed[4].astype(np.int64),
    )
