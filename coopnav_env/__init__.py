"""coopnav: cooperative GNSS navigation for UAV swarms in urban canyons.

Sub-packages
------------
``coopnav_env.gnss``   frames, constellations, error models and pseudorange simulation.
``coopnav_env.nav``    standalone WLS, virtual-centroid cooperative solver (SDT/DDT), master-slave.
``coopnav_env.sim``    the urban world: buildings, line of sight, canyon mask, swarm kinematics.
``coopnav_env.envs``   the PettingZoo parallel environment, its Gymnasium single-agent view and
                       the named observation layout.

Importing the package registers the Gymnasium ids :data:`GYM_ENV_ID`
(``"coopnav/UrbanCanyonSwarm-v1"``, :class:`coopnav_env.envs.gym_wrapper.UrbanCanyonSwarmV1Env`:
one agent commands the whole swarm of ``urban_canyon_v1``) and the legacy
:data:`GYM_ENV_ID_V0` (``"coopnav/UrbanCanyonSwarm-v0"``, the view of ``urban_canyon_v0``), so
``gymnasium.make(GYM_ENV_ID, **fields)`` works after ``import coopnav_env``. The registration
names the entry point as a string: nothing but Gymnasium's registry is imported until the
environment is made.
"""

__version__ = "0.1.0"

GYM_ENV_ID = "coopnav/UrbanCanyonSwarm-v1"
"""Gymnasium id of the single-agent swarm environment, ``urban_canyon_v1`` (registered on
import)."""

GYM_ENV_ID_V1 = GYM_ENV_ID
"""The same id as :data:`GYM_ENV_ID`, named by its version."""

GYM_ENV_ID_V0 = "coopnav/UrbanCanyonSwarm-v0"
"""Gymnasium id of the single-agent view of the legacy ``urban_canyon_v0`` (registered on
import; making it warns once per process)."""


def _register_gymnasium_envs() -> None:
    """Register :data:`GYM_ENV_ID` and :data:`GYM_ENV_ID_V0` with Gymnasium once (a re-import
    does not warn)."""
    from gymnasium.envs.registration import register, registry

    if GYM_ENV_ID not in registry:
        register(id=GYM_ENV_ID, entry_point="coopnav_env.envs.gym_wrapper:UrbanCanyonSwarmV1Env")
    if GYM_ENV_ID_V0 not in registry:
        register(id=GYM_ENV_ID_V0, entry_point="coopnav_env.envs.gym_wrapper:UrbanCanyonSwarmEnv")


_register_gymnasium_envs()


def _install_old_names() -> None:
    """Keep ``import agents`` / ``training`` / ``reproduction`` working for one release."""
    from coopnav_env.old_names import install

    install()


_install_old_names()
