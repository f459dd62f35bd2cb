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
``gymnasium.make(GYM_ENV_ID, **fields)`` works after ``import coopnav_env``. The ids are
registered when Gymnasium is imported (at once if it already is), with the entry point named as
a string: ``import coopnav_env`` itself imports neither Gymnasium nor the environment.
"""

__version__ = "0.1.0"


def _quiet_interrupt_while_the_command_loads() -> None:
    """Run as the ``coopnav`` command, an interrupt (Ctrl-C) that arrives while the package
    loads ends with one line and status 130 instead of a traceback; the command's own handling
    (:func:`coopnav_env.training.cli.main`) takes over once it runs. Imported as a library (any
    other program, or a worker process the command started), nothing changes."""
    import os
    import signal
    import sys

    argv = getattr(sys, "argv", None) or [""]
    if os.path.splitext(os.path.basename(str(argv[0])))[0] != "coopnav":
        return
    mp = sys.modules.get("multiprocessing")  # a spawned worker has the command's argv too
    if mp is not None and mp.parent_process() is not None:
        return
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return

    def coopnav_interrupted_while_loading(signum: int, frame: object) -> None:
        sys.stderr.write("\ncoopnav: interrupted while starting; nothing was done\n")
        sys.stderr.flush()
        os._exit(128 + signum)

    try:
        signal.signal(signal.SIGINT, coopnav_interrupted_while_loading)
    except ValueError:  # not the main thread: leave the interpreter's handling
        pass


_quiet_interrupt_while_the_command_loads()

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


class _RegisterWhenGymnasiumLoads:
    """A meta-path finder that registers the ids (:func:`_register_gymnasium_envs`) right after
    ``gymnasium`` is first imported, and then leaves ``sys.meta_path``.

    ``import coopnav_env`` thus does not import Gymnasium (a fifth of a second; the ``coopnav``
    command starts handling Ctrl-C sooner), and ``gymnasium.make(GYM_ENV_ID)`` still works
    after ``import coopnav_env`` in either order.
    """

    def find_spec(self, name: str, path: object = None, target: object = None) -> object:
        if name != "gymnasium":
            return None
        import importlib.util
        import sys

        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
            return spec
        run_module = spec.loader.exec_module

        def exec_module(module: object) -> None:
            run_module(module)
            _register_gymnasium_envs()

        spec.loader.exec_module = exec_module  # type: ignore[method-assign]
        return spec


def _register_when_gymnasium_loads() -> None:
    import sys

    if "gymnasium" in sys.modules:
        _register_gymnasium_envs()
    elif not any(isinstance(f, _RegisterWhenGymnasiumLoads) for f in sys.meta_path):
        sys.meta_path.insert(0, _RegisterWhenGymnasiumLoads())


_register_when_gymnasium_loads()


def _install_old_names() -> None:
    """Keep ``import agents`` / ``training`` / ``reproduction`` working for one release."""
    from coopnav_env.old_names import install

    install()


_install_old_names()
