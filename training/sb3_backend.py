"""The Stable-Baselines3 backend of ``coopnav train``: PPO with parameter sharing.

One Stable-Baselines3 PPO policy drives every UAV: SuperSuit turns the PettingZoo swarm into
a vector env with one slot per UAV and concatenates ``n_envs`` swarms
(:mod:`coopnav_env.training.vec_env`, which also makes ``PPO(seed=...)`` work and repeat exactly).
``--backend rllib`` trains on Ray RLlib instead (:mod:`coopnav_env.training.rllib_backend`, same
configuration file and output layout).

Hyperparameters (:class:`coopnav_env.training.config.TrainConfig`) come from the packaged
settings (:func:`coopnav_env.training.config.load_config`: ``run.yaml`` and ``sb3.yaml``) and
can be overridden from the command line. Everything a run produces goes to ``--out DIR``::

    DIR/config.yaml              the resolved configuration, seed included
                                 (a resumed session adds config_resumed_at_<N>.yaml)
    DIR/run.json                 versions, wall time, agent-steps per second
    DIR/final_model.zip          the trained policy (``coopnav_env.agents.ppo`` /
                                 ``ppo:DIR/final_model.zip``)
    DIR/checkpoints/ppo_<N>_steps.zip   periodic checkpoints (N agent-steps)
    DIR/logs/                    TensorBoard events and progress.csv (learning curve)
    DIR/*monitor.csv             one line per finished UAV-episode (return, length, final infos)

``--resume CHECKPOINT`` (or ``--resume latest``) continues an interrupted run: the model, its
optimizer state and its step count are loaded, and training runs until ``timesteps``
agent-steps in total. Checkpoints are written at the start of a rollout, right after a
policy update, so resuming from one loses no collected experience; Ctrl-C (or SIGTERM) also
writes one, at the step count of the last completed update. Interrupts are taken between
environment steps (:func:`coopnav_env.training.runs.interrupts_deferred`), never inside one
(a compiled call). ``logs/progress.csv`` holds every iteration once, in order, over
interrupted and resumed sessions (:class:`coopnav_env.training.runs.ProgressLog`).

Seeds: training resets its swarm copies with ``seed + k`` (``k < n_envs``), then each copy
continues its own generator; a resumed run reseeds with ``seed + num_timesteps`` (modulo the
training seed range) so it does not replay its first episodes. Training seeds are kept below
:data:`coopnav_env.training.envs.EVAL_SEED_START`, where the held-out evaluation seeds begin.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from coopnav_env.training.config import TrainConfig, check_bool, check_number
from coopnav_env.training.envs import EVAL_SEED_START, make_env_fn
from coopnav_env.training.files import atomic_path, write_json, write_yaml
from coopnav_env.training.runs import (
    ProgressLog,
    check_same_environment,
    checkpoint_candidates,
    first_loadable,
    interrupts_deferred,
    open_run,
    raise_if_interrupted,
)

__all__ = [
    "MONITOR_INFO_KEYS",
    "POLICY_KWARGS_RULES",
    "PPO_RULES",
    "behaviour_clone",
    "check",
    "find_latest_checkpoint",
    "resolve_resume",
    "save_checkpoint",
    "save_model",
    "train",
]

CHECKPOINT_RE = re.compile(r"_(\d+)_steps\.zip$")
"""Names of the periodic checkpoints, ``ppo_<N>_steps.zip`` (N agent-steps)."""

MONITOR_INFO_KEYS: tuple[str, ...] = (
    "in_goal",
    "goal_reached",
    "collided",
    "nav_error_m",
    "coop_error_m",
    "goal_distance_m",
)
"""Final-step infos written to ``monitor*.csv`` for each UAV-episode (those the env has)."""


def save_model(model: Any, path: Path) -> Path:
    """``model.save(path)`` through a temporary ``.zip`` in the same folder (atomic)."""
    with atomic_path(path, suffix=".zip") as tmp:
        model.save(tmp)
    return path


def save_checkpoint(model: Any, folder: Path, num_timesteps: int) -> Path:
    """Save ``model`` as ``folder/ppo_<N>_steps.zip`` (atomically), recording ``N`` =
    ``num_timesteps`` agent-steps (which may be fewer than the model counts: the start of
    an unfinished rollout, whose steps are not in the policy)."""
    path = folder / f"ppo_{int(num_timesteps)}_steps.zip"
    saved = model.num_timesteps
    model.num_timesteps = int(num_timesteps)
    try:
        save_model(model, path)
    finally:
        model.num_timesteps = saved
    return path


def find_latest_checkpoint(out: str | Path) -> Path:
    """The newest checkpoint in ``out/checkpoints`` that loads (newer ones that don't are
    skipped, with a warning naming them).

    Raises
    ------
    FileNotFoundError
        There is none.
    """
    from stable_baselines3 import PPO

    folder = Path(out) / "checkpoints"
    candidates = checkpoint_candidates(folder, "*_steps.zip", CHECKPOINT_RE)
    return first_loadable(candidates, lambda p: PPO.load(p, env=None, device="cpu"), folder)[0]


def resolve_resume(cfg: TrainConfig) -> Path | None:
    """The checkpoint ``cfg.resume`` names (``"latest"``: the newest in ``cfg.out``), or None.

    Raises
    ------
    FileNotFoundError
        No such checkpoint.
    """
    if cfg.resume is None:
        return None
    if cfg.resume == "latest":
        return find_latest_checkpoint(cfg.out)
    p = Path(cfg.resume)
    if not p.is_file() and p.with_suffix(".zip").is_file():
        p = p.with_suffix(".zip")
    if not p.is_file():
        raise FileNotFoundError(f"checkpoint to resume from not found: {p}")
    return p


# --------------------------------------------------------------------------------------------
# callbacks (SB3 imported lazily: this module is imported by `coopnav --help`)
# --------------------------------------------------------------------------------------------


def _callbacks() -> tuple[Any, Any, Any]:
    """(navigation metrics, rollout checkpoint, progress bar) callback classes bound to SB3."""
    import numpy as np
    from stable_baselines3.common.callbacks import BaseCallback

    from coopnav_env.envs.urban_canyon import fix_error_m

    class NavMetricsCallback(BaseCallback):
        """Log navigation figures of each rollout to TensorBoard (``nav/...``).

        Reads ``infos`` of every agent-step: mean and median cooperative 3-D error,
        P(error < 3 m) (a step without a cooperative fix counts as a failure), mean
        satellites received; and, over the swarm episodes that ended in the rollout, the
        goal rate (every UAV in the goal area: ``in_goal``) and the collision rate (some UAV
        ``collided``). Vector slots ``k * n_agents .. (k + 1) * n_agents - 1`` are the UAVs
        of swarm copy ``k`` (see :mod:`coopnav_env.training.vec_env`); they finish together.
        """

        def __init__(self, n_agents: int):
            super().__init__()
            self.n_agents = int(n_agents)

        def _on_rollout_start(self) -> None:
            self._err: list[float] = []
            self._sats: list[float] = []
            self._ended = 0
            self._goals = 0
            self._crashes = 0

        def _on_step(self) -> bool:
            infos = self.locals.get("infos", ())
            dones = np.asarray(self.locals.get("dones", np.zeros(len(infos), dtype=bool)))
            for info in infos:
                if info.get("coop_error_m") is not None:
                    self._err.append(fix_error_m(info, "coop_error_m"))
                n = info.get("n_sats")
                if n is not None:
                    self._sats.append(float(n))
            n = self.n_agents
            for k in range(len(infos) // n):
                if not dones[k * n]:
                    continue
                swarm = infos[k * n : (k + 1) * n]
                self._ended += 1
                self._goals += all(
                    bool(i.get("in_goal", i.get("goal_reached", False))) for i in swarm
                )
                self._crashes += any(bool(i.get("collided", False)) for i in swarm)
            return True

        def _on_rollout_end(self) -> None:
            err = np.asarray(self._err, dtype=float)
            fin = err[np.isfinite(err)]
            if err.size:
                self.logger.record("nav/p_coop_error_lt_3m", float(np.mean(err < 3.0)))
            if fin.size:
                self.logger.record("nav/coop_error_mean_m", float(fin.mean()))
                self.logger.record("nav/coop_error_median_m", float(np.median(fin)))
            if self._sats:
                self.logger.record("nav/n_sats_mean", float(np.mean(self._sats)))
            if self._ended:
                self.logger.record("nav/goal_rate", self._goals / self._ended)
                self.logger.record("nav/collision_rate", self._crashes / self._ended)
                self.logger.record("nav/episodes", self._ended)

    class RolloutCheckpointCallback(BaseCallback):
        """Save ``ppo_<N>_steps.zip`` every ``freq`` agent-steps, right after an update.

        Saving at the start of a rollout (not in the middle of one, as SB3's
        ``CheckpointCallback`` does) means a checkpoint holds the policy trained on every
        step it counts: resuming loses no collected experience.
        """

        def __init__(self, freq: int, folder: Path):
            super().__init__()
            self.freq = int(freq)
            self.folder = folder
            self.rollout_start_timesteps = 0
            self.collecting = False
            self._last = -1

        def _init_callback(self) -> None:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._last = self.model.num_timesteps

        def save(self) -> Path:
            """Save now and return the path."""
            return save_checkpoint(self.model, self.folder, int(self.model.num_timesteps))

        def _on_rollout_start(self) -> None:
            self.collecting = True
            self.rollout_start_timesteps = self.model.num_timesteps
            n = self.model.num_timesteps
            if self.freq > 0 and n // self.freq > max(self._last, 0) // self.freq and n > 0:
                self.save()
                self._last = n
            raise_if_interrupted()  # after an update (see runs.interrupts_deferred)

        def _on_rollout_end(self) -> None:
            self.collecting = False

        def _on_step(self) -> bool:
            raise_if_interrupted()  # between environment steps, never inside one
            return True

    class ProgressCallback(BaseCallback):
        """A plain ``tqdm`` progress bar over agent-steps, with the latest episode return.

        SB3's own bar needs ``rich``; this one needs only ``tqdm`` (and prints nothing when
        that is missing).
        """

        def _on_training_start(self) -> None:
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - tqdm is a training dependency
                self.bar = None
                return
            # PPO collects whole rollouts: the run ends at the next multiple of one rollout
            rollout = max(int(getattr(self.model, "n_steps", 1)) * self.training_env.num_envs, 1)
            todo = self.locals["total_timesteps"] - self.model.num_timesteps
            self.bar = tqdm(
                desc="PPO",
                total=-(-todo // rollout) * rollout,
                unit="agent-step",
                unit_scale=True,
                dynamic_ncols=True,
                smoothing=0.1,
                mininterval=0.5,
            )

        def _on_step(self) -> bool:
            if self.bar is not None:
                self.bar.update(self.training_env.num_envs)
            return True

        def _on_rollout_end(self) -> None:
            buf = self.model.ep_info_buffer
            if self.bar is not None and buf:
                self.bar.set_postfix(ep_return=f"{np.mean([e['r'] for e in buf]):.2f}")

        def _on_training_end(self) -> None:
            if self.bar is not None:
                self.bar.close()

    return NavMetricsCallback, RolloutCheckpointCallback, ProgressCallback


# --------------------------------------------------------------------------------------------
# training
# --------------------------------------------------------------------------------------------


def behaviour_clone(
    model: Any,
    env_fn: Callable[[], Any],
    spec: Mapping[str, Any],
    seed: int = 0,
    progress: bool = False,
) -> dict[str, Any]:
    """Fit a fresh PPO model to a teacher policy (behaviour cloning) before PPO starts.

    The teacher flies ``spec["episodes"]`` episodes of the training environment (reset seeds
    ``EVAL_SEED_START // 2 + seed + i``, below the held-out evaluation seeds). The actor's
    mean action is fitted to the teacher's actions (mean squared error; the log-std is left
    at ``log_std_init``, so PPO keeps exploring), and the critic to the teacher's discounted
    returns (``gamma`` of the model; rewards scaled like ``VecNormalize`` when the model's
    environment normalises them), for ``spec["epochs"]`` passes with Adam.

    ``progress`` shows two ``tqdm`` bars on stderr (teacher episodes, then fitting epochs);
    they change nothing in the result.

    Returns
    -------
    dict
        Samples, teacher goal rate and final losses (written to ``pretrain.json``).
    """
    import numpy as np
    import torch

    from coopnav_env.agents import make_policy

    env = env_fn()
    teacher = make_policy(str(spec["policy"]), env, **dict(spec.get("policy_kwargs") or {}))
    gamma = float(model.gamma)
    obs_all: list[np.ndarray] = []
    act_all: list[np.ndarray] = []
    ret_all: list[np.ndarray] = []
    goals = 0
    for i in _bar(range(int(spec["episodes"])), progress, "warm start: teacher", "episode"):
        ep_seed = EVAL_SEED_START // 2 + seed + i
        obs, _ = env.reset(seed=ep_seed)
        teacher.reset(seed=ep_seed)
        ep_obs, ep_act, ep_rew = [], [], []
        infos: dict[str, Any] = {}
        while env.agents:
            raise_if_interrupted()  # between steps (see runs.interrupts_deferred)
            agents = list(env.agents)
            act = teacher.act(obs)
            ep_obs.append(np.stack([obs[a] for a in agents]))
            ep_act.append(np.stack([np.clip(act[a], -1.0, 1.0) for a in agents]))
            obs, rew, _te, _tr, infos = env.step(act)
            ep_rew.append(np.array([rew[a] for a in agents]))
        goals += bool(infos) and all(bool(v.get("in_goal", False)) for v in infos.values())
        rets = np.zeros_like(np.stack(ep_rew))
        acc = np.zeros(rets.shape[1])
        for t in range(len(ep_rew) - 1, -1, -1):
            acc = ep_rew[t] + gamma * acc
            rets[t] = acc
        obs_all += ep_obs
        act_all += ep_act
        ret_all.append(rets.reshape(-1))
    env.close()
    x = torch.as_tensor(np.concatenate(obs_all), dtype=torch.float32, device=model.device)
    y = torch.as_tensor(np.concatenate(act_all), dtype=torch.float32, device=model.device)
    r = np.concatenate(ret_all)
    ret_scale = float(np.std(r)) if getattr(model.get_env(), "norm_reward", False) else 1.0
    v = torch.as_tensor(r / max(ret_scale, 1e-8), dtype=torch.float32, device=model.device)
    policy = model.policy
    params = [p for name, p in policy.named_parameters() if name != "log_std"]
    opt = torch.optim.Adam(params, lr=float(spec["learning_rate"]))
    gen = torch.Generator().manual_seed(int(seed))
    batch = 256
    pi_loss = vf_loss = float("nan")
    policy.set_training_mode(True)
    for _ in _bar(range(int(spec["epochs"])), progress, "warm start: fitting", "epoch"):
        raise_if_interrupted()
        perm = torch.randperm(x.shape[0], generator=gen)
        for k in range(0, x.shape[0], batch):
            idx = perm[k : k + batch]
            features = policy.extract_features(x[idx])
            if isinstance(features, tuple):  # separate actor/critic feature extractors
                latent_pi = policy.mlp_extractor.forward_actor(features[0])
                latent_vf = policy.mlp_extractor.forward_critic(features[1])
            else:
                latent_pi, latent_vf = policy.mlp_extractor(features)
            mean = policy.action_net(latent_pi)
            value = policy.value_net(latent_vf).squeeze(-1)
            loss_pi = torch.mean((mean - y[idx]) ** 2)
            loss_vf = torch.mean((value - v[idx]) ** 2)
            opt.zero_grad()
            (loss_pi + 0.5 * loss_vf).backward()
            opt.step()
            pi_loss, vf_loss = loss_pi.item(), loss_vf.item()
    policy.set_training_mode(False)
    return {
        "teacher": str(spec["policy"]),
        "episodes": int(spec["episodes"]),
        "samples": int(x.shape[0]),
        "teacher_goal_rate": goals / max(int(spec["episodes"]), 1),
        "return_scale": ret_scale,
        "final_action_mse": pi_loss,
        "final_value_mse": vf_loss,
    }


def _bar(items: range, show: bool, desc: str, unit: str) -> Any:
    """``items`` behind a ``tqdm`` progress bar on stderr when ``show`` (and tqdm is there)."""
    if not show:
        return items
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a training dependency
        return items
    return tqdm(items, desc=desc, unit=unit, dynamic_ncols=True, mininterval=0.5)


def train(cfg: TrainConfig) -> Path:
    """Train a parameter-sharing PPO policy and return the path of the final model.

    Every setting is checked (:func:`check`) and the environment built once before anything
    is written; then the run folder is opened (:func:`coopnav_env.training.runs.open_run`: lock,
    fresh / overwrite / resume rules, SIGINT and SIGTERM handled from there on).

    Parameters
    ----------
    cfg : TrainConfig

    Returns
    -------
    pathlib.Path
        ``cfg.out / "final_model.zip"`` (also when ``cfg.resume`` finds the run finished with
        at least ``cfg.timesteps`` agent-steps: then nothing is touched).

    Raises
    ------
    FileNotFoundError
        ``cfg.resume`` names a checkpoint that does not exist, or none loads.
    ValueError
        Bad settings, a checkpoint that does not load, an unusable run folder
        (:class:`coopnav_env.training.runs.RunFolderError`).
    KeyboardInterrupt
        (:class:`coopnav_env.training.runs.Interrupted` for SIGINT/SIGTERM) re-raised after
        writing a checkpoint (``checkpoints/ppo_<N>_steps.zip``) and saying what was saved.
    """
    check(cfg)
    env_fn = make_env_fn(cfg.env_id, cfg.env)
    probe = env_fn()  # validates the env kwargs before anything is written
    n_agents = len(probe.possible_agents)
    _, probe_infos = probe.reset(seed=0)
    info_keys = set(probe_infos.get(probe.possible_agents[0], {}))
    probe.close()
    monitor_keys = tuple(k for k in MONITOR_INFO_KEYS if k in info_keys)

    with open_run(cfg) as run:
        if cfg.resume == "latest" and run.nothing_to_do(cfg.timesteps):
            run.say_finished()
            return Path(cfg.out) / "final_model.zip"
        resume_path, start_steps = _resume_point(cfg, run.finished)
        if resume_path is not None:
            check_same_environment(cfg, Path(cfg.out) / "config.yaml")
            if run.nothing_to_do(cfg.timesteps):  # e.g. --resume RUN/final_model.zip
                run.say_finished()
                return Path(cfg.out) / "final_model.zip"
            if start_steps > cfg.timesteps:
                raise ValueError(
                    f"--timesteps {cfg.timesteps} is below the {start_steps} agent-steps of the "
                    f"checkpoint {resume_path}: nothing would be trained; ask for more "
                    f"(--timesteps M with M > {start_steps})"
                )
        return _train_in_folder(cfg, env_fn, n_agents, monitor_keys, resume_path, start_steps)


def check(cfg: TrainConfig) -> None:
    """Check the settings only this backend reads (``ppo``, ``device``), before any work.

    Every key of ``ppo`` must be an argument of Stable-Baselines3's ``PPO`` and every value
    one it accepts (:data:`PPO_RULES`; SB3 itself would reject many only when the model is
    built or the first rollout ends, and accepts some it should not, such as ``gamma: 2``);
    ``ppo.policy_kwargs`` must hold arguments of its ``ActorCriticPolicy``.

    Raises
    ------
    ValueError
        The message names the setting and the values it accepts.
    ImportError
        Stable-Baselines3 (or torch) is not installed.
    """
    import inspect

    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.policies import ActorCriticPolicy

    ppo = dict(cfg.ppo)
    policy = ppo.pop("policy", "MlpPolicy")
    if not (isinstance(policy, str) and policy in PPO.policy_aliases) and not isinstance(
        policy, type
    ):
        raise ValueError(f"ppo.policy must be one of {sorted(PPO.policy_aliases)}, got {policy!r}")
    valid = set(inspect.signature(PPO.__init__).parameters) - {"self", "policy", "env", "seed"}
    valid -= {"device", "tensorboard_log", "verbose", "_init_setup_model"}
    unknown = sorted(set(ppo) - valid)
    if unknown:
        raise ValueError(f"unknown PPO setting(s) {unknown}; valid settings: {sorted(valid)}")
    for key, value in ppo.items():
        rule = PPO_RULES.get(key)
        if rule is not None:
            rule(f"ppo.{key}", value)
    kwargs = ppo.get("policy_kwargs") or {}
    if not isinstance(kwargs, Mapping):
        raise ValueError(f"ppo.policy_kwargs must be a mapping, got {kwargs!r}")
    allowed = set(inspect.signature(ActorCriticPolicy.__init__).parameters)
    allowed -= {"self", "observation_space", "action_space", "lr_schedule"}
    unknown = sorted(set(kwargs) - allowed)
    if unknown:
        raise ValueError(
            f"unknown ppo.policy_kwargs setting(s) {unknown}; valid settings: {sorted(allowed)}"
        )
    for key, value in kwargs.items():
        rule = POLICY_KWARGS_RULES.get(key, _a_class if key.endswith("_class") else None)
        if rule is not None:
            rule(f"ppo.policy_kwargs.{key}", value)
    device = cfg.device
    if device != "auto":
        try:
            torch.device(device)
        except (RuntimeError, TypeError) as exc:
            raise ValueError(
                f"device must be a PyTorch device such as cpu, cuda, cuda:0, mps or auto, "
                f"got {device!r}"
            ) from exc


def _net_arch(name: str, value: Any) -> None:
    """``net_arch``: a list of layer sizes, or ``{pi: [...], vf: [...]}``."""

    def sizes(v: Any) -> bool:
        return isinstance(v, (list, tuple)) and all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in v
        )

    ok = sizes(value) or (
        isinstance(value, Mapping)
        and set(value) <= {"pi", "vf"}
        and all(map(sizes, value.values()))
    )
    if not ok:
        raise ValueError(
            f"{name} must be a list of layer sizes (integers >= 1), e.g. [128, 128], or "
            f"{{pi: [...], vf: [...]}}, got {value!r}"
        )


def _rule(**kw: Any) -> Callable[[str, Any], None]:
    return lambda name, value: check_number(name, value, **kw)


PPO_RULES: dict[str, Callable[[str, Any], None]] = {
    "learning_rate": _rule(lo=0.0, lo_open=True),
    "n_steps": _rule(integer=True, lo=1),
    "batch_size": _rule(integer=True, lo=2),  # SB3 normalises advantages per mini-batch
    "n_epochs": _rule(integer=True, lo=1),
    "gamma": _rule(lo=0.0, hi=1.0, lo_open=True),
    "gae_lambda": _rule(lo=0.0, hi=1.0),
    "clip_range": _rule(lo=0.0, lo_open=True),
    "clip_range_vf": _rule(lo=0.0, lo_open=True, none=True),
    "normalize_advantage": check_bool,
    "ent_coef": _rule(lo=0.0),
    "vf_coef": _rule(lo=0.0),
    "max_grad_norm": _rule(lo=0.0, lo_open=True),
    "use_sde": check_bool,
    "sde_sample_freq": _rule(integer=True, lo=-1),
    "target_kl": _rule(lo=0.0, lo_open=True, none=True),
    "stats_window_size": _rule(integer=True, lo=1),
}
"""What each PPO setting accepts (a function raising ``ValueError`` that names it)."""


def _a_class(name: str, value: Any) -> None:
    if not isinstance(value, type):
        raise ValueError(
            f"{name} must be a Python class (e.g. torch.nn.ReLU; it can't be set from YAML), "
            f"got {value!r}"
        )


POLICY_KWARGS_RULES: dict[str, Callable[[str, Any], None]] = {
    "net_arch": _net_arch,
    "activation_fn": _a_class,
    "log_std_init": _rule(),
    "ortho_init": check_bool,
    "full_std": check_bool,
    "use_expln": check_bool,
    "squash_output": check_bool,
    "share_features_extractor": check_bool,
    "normalize_images": check_bool,
}
"""What each ``ppo.policy_kwargs`` setting accepts."""


def _progress_csv(path: Path, resumed_at: int | None) -> Any:
    """SB3's CSV log as a :class:`coopnav_env.training.runs.ProgressLog` (every iteration once,
    in order, over resumed sessions; atomic rewrites) keyed by ``time/total_timesteps``."""
    from numbers import Number

    from stable_baselines3.common.logger import KVWriter, filter_excluded_keys

    class ProgressCSV(KVWriter):
        def __init__(self) -> None:
            self.log = ProgressLog(path, "time/total_timesteps", resumed_at)

        def write(
            self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0
        ) -> None:
            row = filter_excluded_keys(key_values, key_excluded, "csv")
            self.log.append({k: v for k, v in row.items() if isinstance(v, Number | str)})

        def close(self) -> None:
            pass

    return ProgressCSV()


def _resume_point(cfg: TrainConfig, finished: Mapping[str, Any] | None) -> tuple[Path | None, int]:
    """(checkpoint to resume from, its agent-steps), or (None, 0) for a fresh run.

    ``"latest"``: the newest checkpoint in ``cfg.out/checkpoints`` (or the final model of a
    finished run being trained further) that loads; newer ones that don't are skipped and
    named. An explicit path must load.
    """
    from stable_baselines3 import PPO

    if cfg.resume is None:
        return None, 0

    def load(path: Path) -> int:
        return int(PPO.load(path, env=None, device="cpu").num_timesteps)

    if cfg.resume == "latest":
        final = None
        if finished is not None:
            final = (int(finished["num_timesteps"]), Path(cfg.out) / "final_model.zip")
        folder = Path(cfg.out) / "checkpoints"
        candidates = checkpoint_candidates(folder, "*_steps.zip", CHECKPOINT_RE, final)
        path, steps = first_loadable(candidates, load, folder)
        return path, steps
    path = resolve_resume(cfg)
    try:
        return path, load(path)
    except Exception as exc:
        raise ValueError(f"cannot resume from {path}: it does not load ({exc})") from exc


def _train_in_folder(
    cfg: TrainConfig,
    env_fn: Callable[[], Any],
    n_agents: int,
    monitor_keys: tuple[str, ...],
    resume_path: Path | None,
    start_steps: int,
) -> Path:
    """The training itself, in the opened (locked) run folder."""
    import numpy as np
    import stable_baselines3
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger, TensorBoardOutputFormat
    from stable_baselines3.common.vec_env import VecMonitor

    from coopnav_env.training.vec_env import make_vec_env

    out = Path(cfg.out)
    ppo_kwargs = dict(cfg.ppo)
    policy = ppo_kwargs.pop("policy", "MlpPolicy")
    torch.set_num_threads(cfg.torch_threads)
    resolved = cfg.to_dict()
    resolved["resume"] = str(resume_path) if resume_path else None
    resolved["agent_steps_per_env_step"] = cfg.n_envs * n_agents
    vec_kind = cfg.vec_env_kind()
    resolved["vec_env_kind"] = vec_kind  # what "auto" became
    # the original config.yaml stays: `coopnav evaluate` reads the environment from it (a run
    # resumed from another folder's checkpoint, or whose config.yaml is gone, writes one)
    fresh_config = start_steps == 0 or not (out / "config.yaml").is_file()
    name = "config.yaml" if fresh_config else f"config_resumed_at_{start_steps}.yaml"
    write_yaml(out / name, resolved)
    checkpoints = out / "checkpoints"

    model = monitor = None
    phase = "setting up"
    nav_cls, ckpt_cls, progress_cls = _callbacks()
    ckpt = ckpt_cls(cfg.checkpoint_freq, checkpoints)
    try:
        with interrupts_deferred():
            venv = make_vec_env(env_fn, cfg.n_envs, cfg.num_cpus, kind=vec_kind)
            suffix = "" if start_steps == 0 else f"_resumed_at_{start_steps}"
            monitor = VecMonitor(
                venv,
                # SB3 appends ".monitor.csv" to any other name
                filename=str(
                    out / ("monitor.csv" if not suffix else f"resumed_at_{start_steps}.monitor.csv")
                ),
                info_keywords=monitor_keys,
            )
            learn_env: Any = monitor
            if cfg.normalize_reward:
                from stable_baselines3.common.vec_env import VecNormalize

                learn_env = VecNormalize(
                    monitor,
                    norm_obs=False,
                    norm_reward=True,
                    gamma=float(ppo_kwargs.get("gamma", 0.99)),
                )
            if resume_path is not None:
                model = PPO.load(resume_path, env=learn_env, device=cfg.device)
                env_seed = (cfg.seed + start_steps) % (EVAL_SEED_START - cfg.n_envs)
                model.set_random_seed(env_seed)
            else:
                model = PPO(
                    policy,
                    learn_env,
                    seed=cfg.seed,
                    device=cfg.device,
                    verbose=cfg.verbose,
                    **ppo_kwargs,
                )
                if cfg.pretrain:
                    phase = "the behaviour-cloning warm start"
                    print(
                        f"behaviour-cloning warm start: {cfg.pretrain['episodes']} episodes of the "
                        f"{cfg.pretrain['policy']} teacher, {cfg.pretrain['epochs']} epochs",
                        file=sys.stderr,
                        flush=True,
                    )
                    stats = behaviour_clone(
                        model, env_fn, cfg.pretrain, seed=cfg.seed, progress=cfg.progress_bar
                    )
                    write_json(out / "pretrain.json", stats)
            phase = "PPO"
            logs = out / "logs"
            logs.mkdir(exist_ok=True)
            formats = [
                TensorBoardOutputFormat(str(logs)),
                _progress_csv(logs / "progress.csv", start_steps if resume_path else None),
            ]
            if cfg.verbose:
                from stable_baselines3.common.logger import HumanOutputFormat

                formats.append(HumanOutputFormat(sys.stdout))
            model.set_logger(Logger(str(logs), formats))

            remaining = cfg.timesteps - start_steps
            t0 = time.perf_counter()
            if remaining > 0:
                model.learn(
                    total_timesteps=remaining,
                    callback=[nav_cls(n_agents), ckpt]
                    + ([progress_cls()] if cfg.progress_bar else []),
                    reset_num_timesteps=resume_path is None,
                )
            wall_s = time.perf_counter() - t0
    except KeyboardInterrupt:
        if model is None:
            print(
                f"\ninterrupted while {phase}: no checkpoint (nothing was trained yet); "
                f"start again with --overwrite, or --resume if {checkpoints} holds one",
                file=sys.stderr,
            )
        else:
            n = ckpt.rollout_start_timesteps if ckpt.collecting else int(model.num_timesteps)
            path = save_checkpoint(model, checkpoints, n)
            what = (
                "the policy with an incomplete warm start (PPO had not started)"
                if phase != "PPO"
                else f"the policy after {n} agent-steps"
            )
            print(
                f"\ninterrupted during {phase}: saved {what} to {path}; continue with "
                f"--resume latest (or --resume {path})",
                file=sys.stderr,
            )
        raise
    finally:
        if monitor is not None:
            monitor.close()
    final = out / "final_model.zip"
    save_model(model, final)
    done_steps = int(model.num_timesteps) - start_steps
    info = {
        "final_model": str(final),
        "seed": cfg.seed,
        "num_timesteps": int(model.num_timesteps),
        "session_agent_steps": done_steps,
        "session_wall_s": round(wall_s, 3),
        "agent_steps_per_s": round(done_steps / wall_s, 1) if wall_s > 0 and done_steps else None,
        "vec_env": vec_kind,
        "resumed_from": str(resume_path) if resume_path else None,
        "versions": {
            "python": sys.version.split()[0],
            "numpy": np.__version__,
            "torch": torch.__version__,
            "stable_baselines3": stable_baselines3.__version__,
        },
    }
    write_json(out / "run.json", info)
    return final
