"""Policies for ``urban_canyon_v0`` behind one small protocol
(:class:`coopnav_env.agents.base.Policy`).

========================  ==================================================================
name                      policy
========================  ==================================================================
``random``                uniform random velocity commands
                          (:mod:`coopnav_env.agents.random_policy`)
``column``                the swarm flies the street network to the goal as a rigid column
                          at the start altitude, ignoring navigation quality
                          (:mod:`coopnav_env.agents.heuristics`, as below)
``sky_column``            ``column`` that climbs and shifts each UAV toward open sky while
                          keeping contact with its neighbours
``stretched_column``      ``sky_column`` as a stretched column (20 m spacing) that closes up
                          at the goal
``wide_column``           ``stretched_column`` 45 m apart, opening ahead of the start and
                          closing at the goal
``high_wide_column``      ``wide_column`` 60 m apart at 10 m/s, holding the top of the
                          altitude band
``guarded_column``        ``wide_column`` with a wall guard (range sensor) and soft slot
                          tracking, for degraded navigation
``ceiling_column``        ``guarded_column`` that climbs at once and holds the top of the
                          altitude band
``best_sky_route``        ``ceiling_column`` on the street route with the best sky: of the
                          equally short routes, the one with the fewest points of poor
                          satellite geometry predicted by the city map
``waypoint``              each UAV flies toward its next route waypoint from its own
                          observation only (:mod:`coopnav_env.agents.heuristics`)
``setpoints``             fixed route-frame set-points (speed, offset, altitude) for
                          every UAV, each ``speed_step_mps`` slower than the one before;
                          needs ``action_frame="route"``
``ppo:<path>``            a PPO model saved by ``coopnav train`` (:mod:`coopnav_env.agents.ppo`)
``rllib:<path>``          an RLlib checkpoint of ``coopnav train --backend rllib``
                          (:mod:`coopnav_env.agents.rllib_policy`; needs the ``ray`` extra)
``mappo:<path>``          a TorchRL MAPPO or IPPO checkpoint of ``coopnav train --backend
``ippo:<path>``           torchrl`` (:mod:`coopnav_env.agents.marl_policy`; needs the ``marl``
                          extra);
                          ``<path>`` a ``.pt`` file or a run folder; ``mappo:pretrained``
                          (``ippo:pretrained``, ``.../s1``) the shipped study policies
========================  ==================================================================

The column heuristics are one policy, :class:`~coopnav_env.agents.heuristics.ColumnPolicy`,
with named settings (:data:`~coopnav_env.agents.heuristics.COLUMN_PRESETS`). Their earlier
names (``formation``, ``sky``, ``spread``, ``wide``, ``guarded``, ``ceiling``, ``skyroute``)
are accepted for one release with a ``DeprecationWarning`` naming the new one
(:data:`~coopnav_env.agents.heuristics.COLUMN_ALIASES`). A heuristic takes options after ``@`` as
``key=value`` pairs separated by commas, e.g. ``waypoint@altitude_m=28`` or
``column@cruise_speed_mps=5,spacing_m=10``; values are read as Python literals (numbers,
strings, ``True``/``False``). An unknown option or a bad value raises ``ValueError`` naming it.

>>> from coopnav_env import urban_canyon_v0  # doctest: +SKIP
>>> env = urban_canyon_v0.parallel_env()  # doctest: +SKIP
>>> policy = make_policy("column", env)  # doctest: +SKIP
>>> obs, infos = env.reset(seed=1); policy.reset(seed=1)  # doctest: +SKIP
>>> obs, rewards, terms, truncs, infos = env.step(policy.act(obs))  # doctest: +SKIP

Your own policy (any class with the :class:`~coopnav_env.agents.base.Policy` protocol) gets a
name with :func:`register_policy`; :func:`make_policy`, and with it
``coopnav_env.training.evaluate.evaluate``, then make it like a built-in one
(``examples/evaluate_own_policy.py``).
"""

from __future__ import annotations

from coopnav_env.old_names import redirect as _redirect_old_name

# imported as 'agents' (a source checkout): becomes 'coopnav_env.agents'
_redirect_old_name(__name__)

from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

from coopnav_env.agents.base import Policy, clip_actions  # noqa: E402

__all__ = [
    "COLUMN_PRESET_NAMES",
    "POLICY_NAMES",
    "ROUTE_FRAME_HEURISTICS",
    "Policy",
    "action_frame_of",
    "clip_actions",
    "make_policy",
    "parse_policy_name",
    "register_policy",
]

COLUMN_PRESET_NAMES: tuple[str, ...] = (
    "column",
    "sky_column",
    "stretched_column",
    "wide_column",
    "high_wide_column",
    "guarded_column",
    "ceiling_column",
    "best_sky_route",
    "formation",
    "sky",
    "spread",
    "wide",
    "guarded",
    "ceiling",
    "skyroute",
)
"""The column heuristics' names: the presets of
:data:`coopnav_env.agents.heuristics.COLUMN_PRESETS`, then their earlier names
(:data:`~coopnav_env.agents.heuristics.COLUMN_ALIASES`, deprecated)."""

POLICY_NAMES: tuple[str, ...] = (
    "random",
    *COLUMN_PRESET_NAMES,
    "waypoint",
    "setpoints",
    "ppo:<path>",
    "rllib:<path>",
    "mappo:<path>",
    "ippo:<path>",
)
"""Names :func:`make_policy` accepts (plus those given to :func:`register_policy`)."""

ROUTE_FRAME_HEURISTICS: frozenset[str] = frozenset({"setpoints"})
"""The heuristics whose actions are route-frame set-points (``action_frame="route"``); the
other heuristics command velocities (``action_frame="velocity"``)."""

_REGISTERED: dict[str, Callable[..., Policy]] = {}


def action_frame_of(name: str) -> str | None:
    """The action frame (``UrbanCanyonConfig.action_frame``) the heuristic ``name`` flies in.

    ``"route"`` for :data:`ROUTE_FRAME_HEURISTICS`, ``"velocity"`` for the other built-in
    heuristics, and None for a trained policy (``kind:<path>``) or one given to
    :func:`register_policy`: those fly the frame of the environment they are given (a
    trained policy's is its run's). Options after ``@`` are ignored.
    """
    base = name.partition("@")[0]
    if ":" in base or base in _REGISTERED:
        return None
    return "route" if base in ROUTE_FRAME_HEURISTICS else "velocity"


def make_policy(name: str, env: Any, **kwargs: Any) -> Policy:
    """Make the policy called ``name`` for ``env``.

    Parameters
    ----------
    name : str
        One of :data:`POLICY_NAMES`; ``ppo:<path>`` loads the SB3 model at ``<path>``,
        ``rllib:<path>`` the shared policy of an RLlib checkpoint.
    env : pettingzoo.ParallelEnv
        The environment the policy acts in (spaces; map and goal for the heuristics).
    **kwargs
        Passed to the policy's constructor (e.g. ``seed`` for ``random``, ``device`` for
        ``ppo``).

    Returns
    -------
    Policy

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones), or an empty ``ppo:``/``rllib:`` path.
    FileNotFoundError
        ``ppo:<path>`` or ``rllib:<path>`` names a checkpoint that does not exist.
    ImportError
        ``rllib:<path>`` without Ray RLlib installed.
    """
    if not isinstance(name, str):
        raise ValueError(f"policy name must be a string, got {name!r}")
    if "@" in name and ":" not in name.split("@", 1)[0]:
        base, options = parse_policy_name(name)
        try:
            return make_policy(base, env, **{**options, **kwargs})
        except (TypeError, ValueError) as exc:  # an option the constructor rejects
            raise ValueError(f"bad option for policy {base!r} in {name!r}: {exc}") from None
    if name in _REGISTERED:
        policy = _REGISTERED[name](env, **kwargs)
        if not isinstance(policy, Policy):
            raise ValueError(
                f"the factory registered as {name!r} returned {type(policy).__name__}, which "
                "lacks the Policy protocol (name, reset(seed), act(observations))"
            )
        return policy
    if name == "random":
        from coopnav_env.agents.random_policy import RandomPolicy

        return RandomPolicy(env, **kwargs)
    if name in COLUMN_PRESET_NAMES:
        from coopnav_env.agents.heuristics import column_policy

        return column_policy(name, env, **kwargs)
    if name == "waypoint":
        from coopnav_env.agents.heuristics import waypoint_policy

        return waypoint_policy(env, **kwargs)
    if name == "setpoints":
        from coopnav_env.agents.heuristics import setpoint_policy

        return setpoint_policy(env, **kwargs)
    if name.startswith("ppo:"):
        path = name[len("ppo:") :]
        if not path:
            raise ValueError("policy 'ppo:<path>' needs the path of a saved model")
        from coopnav_env.agents.ppo import PPOPolicy

        return PPOPolicy(env, path, **kwargs)
    if name.startswith("rllib:"):
        path = name[len("rllib:") :]
        if not path:
            raise ValueError("policy 'rllib:<path>' needs the path of an RLlib checkpoint")
        from coopnav_env.agents.rllib_policy import RLlibPolicy

        return RLlibPolicy(env, path, **kwargs)
    for prefix in ("mappo:", "ippo:", "torchrl:"):
        if name.startswith(prefix):
            path = name[len(prefix) :]
            if not path:
                raise ValueError(f"policy '{prefix}<path>' needs the path of a TorchRL checkpoint")
            from coopnav_env.agents.marl_policy import MARLPolicy

            algorithm = {"mappo:": "mappo", "ippo:": "ippo"}.get(prefix)  # torchrl: either
            return MARLPolicy(env, path, make_base=make_policy, algorithm=algorithm, **kwargs)
    valid = ", ".join([*POLICY_NAMES, *_REGISTERED])
    raise ValueError(f"unknown policy {name!r}; valid policies: {valid}")


def register_policy(name: str, factory: Callable[..., Policy], *, overwrite: bool = False) -> None:
    """Give your own policy a name that :func:`make_policy` (and so evaluation) accepts.

    After ``register_policy("mine", MyPolicy)``, ``make_policy("mine", env, **kwargs)`` returns
    ``MyPolicy(env, **kwargs)``, ``"mine@key=value"`` passes options as for the heuristics, and
    ``coopnav_env.training.evaluate.evaluate(["column", "mine"], seeds)`` flies it on the
    same held-out episodes as the built-in policies. The registry lives in this process only.

    Parameters
    ----------
    name : str
        A Python identifier, not a built-in name (``random``, the column heuristics'
        names such as ``column``, ``waypoint``, ``setpoints``, ``ppo``, ``rllib``, ``mappo``,
        ``ippo``).
    factory : callable
        ``factory(env, **kwargs)`` returns an object with the
        :class:`~coopnav_env.agents.base.Policy` protocol (``env``: the PettingZoo parallel
        environment of the evaluation).
    overwrite : bool, default False
        Replace an earlier registration of ``name`` instead of raising.

    Raises
    ------
    ValueError
        A bad or built-in name, a factory that is not callable, or ``name`` registered
        already (without ``overwrite``).
    """
    builtin = {n.split(":")[0] for n in POLICY_NAMES}
    if not isinstance(name, str) or not name.isidentifier() or name in builtin:
        raise ValueError(
            f"policy name must be a Python identifier other than {sorted(builtin)}, got {name!r}"
        )
    if not callable(factory):
        raise ValueError(f"factory of policy {name!r} must be callable, got {factory!r}")
    if name in _REGISTERED and not overwrite and _REGISTERED[name] is not factory:
        raise ValueError(
            f"policy {name!r} is registered already; pass overwrite=True to replace it"
        )
    _REGISTERED[name] = factory


def parse_policy_name(name: str) -> tuple[str, dict[str, Any]]:
    """Split ``"waypoint@altitude_m=28,cruise_speed_mps=5"`` into a name and keyword options.

    Values are read as Python literals (numbers, strings, ``True``/``False``), else kept as
    text; a name without ``@`` has no options. A malformed item raises ``ValueError``.
    """
    if "@" not in name:
        return name, {}
    import ast

    base, _, text = name.partition("@")
    options: dict[str, Any] = {}
    for item in text.split(","):
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not key.isidentifier():
            raise ValueError(
                f"bad policy option {item!r} in {name!r}: expected key=value pairs separated "
                "by commas, e.g. 'waypoint@altitude_m=28'"
            )
        try:
            options[key] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            options[key] = value.strip()
    return base, options
