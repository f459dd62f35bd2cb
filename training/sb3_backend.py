"""The Stable-Baselines3 backend of ``coopnav train``: PPO with parameter sharing.

One Stable-Baselines3 PPO policy drives every UAV: SuperSuit turns the PettingZoo swarm into
a vector env with one slot per UAV and concatenates ``n_envs`` swarms
(:mod:`training.vec_env`, which also makes ``PPO(seed=...)`` work and repeat exactly).
``--backend rllib`` trains on Ray RLlib instead (:mod:`training.rllib_backend`, same
configuration file and output layout).

Hyperparameters (:class:`training.config.TrainConfig`) come from
``training/configs/ppo.yaml`` (section ``urban_canyon_v0``) and
can be overridden from the command line. Everything a run produces goes to ``--out DIR``::

    DIR/config.yaml              the resolved configuration, seed included
                                 (a resumed session adds config_resumed_at_<N>.yaml)
    DIR/run.json                 versions, wall time, agent-steps per second
    DIR/final_model.zip          the trained policy (``agents.ppo`` / ``ppo:DIR/final_model.zip``)
    DIR/checkpoints/ppo_<N>_steps.zip   periodic checkpoints (N agent-steps)
    DIR/logs/                    TensorBoard events and progress*.csv (learning curve)
    DIR/*monitor.csv             one line per finished UAV-episode (return, length, final infos)

``--resume CHECKPOINT`` (or ``--resume latest``) continues an interrupted run: the model, its
optimizer state and its step count are loaded, and training runs until ``timesteps``
agent-steps in total. Checkpoints are written at the start of a rollout, right after a
policy update, so resuming from one loses no collected experience; Ctrl-C (or SIGTERM) also
writes one, at the step count of the last completed update.

Seeds: training resets its swarm copies with ``seed + k`` (``k < n_envs``), then each copy
continues its own generator; a resumed run reseeds with ``seed + num_timesteps`` (modulo the
training seed range) so it does not replay its first episodes. Training seeds are kept below
:data:`training.envs.EVAL_SEED_START`, where the held-out evaluation seeds begin.
"""

from __future__ import annotations

import re
import signal
import sys
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from training.config import TrainConfig
from training.envs import EVAL_SEED_START, make_env_fn
from training.runs import (
    atomic_path,
    check_same_environment,
    latest_numbered,
    sigterm_as_interrupt,
    write_json,
    write_yaml,
)

__all__ = [
    "MONITOR_INFO_KEYS",
    "behaviour_clone",
    "find_latest_checkpoint",
    "resolve_resume",
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


def find_latest_checkpoint(out: str | Path) -> Path:
    """The checkpoint with the most steps in ``out/checkpoints``.

    Raises
    ------
    FileNotFoundError
        There is none.
    """
    return latest_numbered(Path(out) / "checkpoints", "*_steps.zip", CHECKPOINT_RE, "")


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
        of swarm copy ``k`` (see :mod:`training.vec_env`); they finish together.
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

        def save(self, num_timesteps: int | None = None) -> Path:
            """Save now (optionally under a smaller step count) and return the path."""
            n = self.model.num_timesteps if num_timesteps is None else int(num_timesteps)
            path = self.folder / f"ppo_{n}_steps.zip"
            saved = self.model.num_timesteps
            self.model.num_timesteps = n
            try:
                save_model(self.model, path)
            finally:
                self.model.num_timesteps = saved
            return path

        def _on_rollout_start(self) -> None:
            self.collecting = True
            self.rollout_start_timesteps = self.model.num_timesteps
            n = self.model.num_timesteps
            if self.freq > 0 and n // self.freq > max(self._last, 0) // self.freq and n > 0:
                self.save()
                self._last = n

        def _on_rollout_end(self) -> None:
            self.collecting = False

        def _on_step(self) -> bool:
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
    model: Any, env_fn: Callable[[], Any], spec: Mapping[str, Any], seed: int = 0
) -> dict[str, Any]:
    """Fit a fresh PPO model to a teacher policy (behaviour cloning) before PPO starts.

    The teacher flies ``spec["episodes"]`` episodes of the training environment (reset seeds
    ``EVAL_SEED_START // 2 + seed + i``, below the held-out evaluation seeds). The actor's
    mean action is fitted to the teacher's actions (mean squared error; the log-std is left
    at ``log_std_init``, so PPO keeps exploring), and the critic to the teacher's discounted
    returns (``gamma`` of the model; rewards scaled like ``VecNormalize`` when the model's
    environment normalises them), for ``spec["epochs"]`` passes with Adam.

    Returns
    -------
    dict
        Samples, teacher goal rate and final losses (written to ``pretrain.json``).
    """
    import numpy as np
    import torch

    from agents import make_policy

    env = env_fn()
    teacher = make_policy(str(spec["policy"]), env, **dict(spec.get("policy_kwargs") or {}))
    gamma = float(model.gamma)
    obs_all: list[np.ndarray] = []
    act_all: list[np.ndarray] = []
    ret_all: list[np.ndarray] = []
    goals = 0
    for i in range(int(spec["episodes"])):
        ep_seed = EVAL_SEED_START // 2 + seed + i
        obs, _ = env.reset(seed=ep_seed)
        teacher.reset(seed=ep_seed)
        ep_obs, ep_act, ep_rew = [], [], []
        infos: dict[str, Any] = {}
        while env.agents:
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
    for _ in range(int(spec["epochs"])):
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


def train(cfg: TrainConfig) -> Path:
    """Train a parameter-sharing PPO policy and return the path of the final model.

    Parameters
    ----------
    cfg : TrainConfig

    Returns
    -------
    pathlib.Path
        ``cfg.out / "final_model.zip"``.

    Raises
    ------
    FileNotFoundError
        ``cfg.resume`` names a checkpoint that does not exist.
    ValueError
        Unknown environment or PPO setting.
    KeyboardInterrupt
        Re-raised after writing a checkpoint (``checkpoints/ppo_<N>_steps.zip``).
    """
    import inspect

    import numpy as np
    import stable_baselines3
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat
    from stable_baselines3.common.vec_env import VecMonitor

    from training.vec_env import make_vec_env

    out = Path(cfg.out)
    resume_path = resolve_resume(cfg)
    ppo_kwargs = dict(cfg.ppo)
    policy = ppo_kwargs.pop("policy", "MlpPolicy")
    valid = set(inspect.signature(PPO.__init__).parameters) - {"self", "policy", "env", "seed"}
    valid -= {"device", "tensorboard_log", "verbose", "_init_setup_model"}
    unknown = sorted(set(ppo_kwargs) - valid)
    if unknown:
        raise ValueError(f"unknown PPO setting(s) {unknown}; valid settings: {sorted(valid)}")

    env_fn = make_env_fn(cfg.env_id, cfg.env)
    probe = env_fn()  # validates the env kwargs before anything is written
    n_agents = len(probe.possible_agents)
    _, probe_infos = probe.reset(seed=0)
    info_keys = set(probe_infos.get(probe.possible_agents[0], {}))
    probe.close()
    monitor_keys = tuple(k for k in MONITOR_INFO_KEYS if k in info_keys)

    start_steps = 0
    if resume_path is not None:
        model = PPO.load(resume_path, env=None, device=cfg.device)
        start_steps = int(model.num_timesteps)
        del model
        check_same_environment(cfg, out / "config.yaml")

    out.mkdir(parents=True, exist_ok=True)
    torch.set_num_threads(cfg.torch_threads)
    resolved = cfg.to_dict()
    resolved["resume"] = str(resume_path) if resume_path else None
    resolved["agent_steps_per_env_step"] = cfg.n_envs * n_agents
    vec_kind = cfg.vec_env_kind()
    resolved["vec_env_kind"] = vec_kind  # what "auto" became
    # the original config.yaml stays: `coopnav evaluate` reads the environment from it
    name = "config.yaml" if start_steps == 0 else f"config_resumed_at_{start_steps}.yaml"
    write_yaml(out / name, resolved)

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
            monitor, norm_obs=False, norm_reward=True, gamma=float(ppo_kwargs.get("gamma", 0.99))
        )
    if resume_path is not None:
        model = PPO.load(resume_path, env=learn_env, device=cfg.device)
        env_seed = (cfg.seed + start_steps) % (EVAL_SEED_START - cfg.n_envs)
        model.set_random_seed(env_seed)
    else:
        model = PPO(
            policy, learn_env, seed=cfg.seed, device=cfg.device, verbose=cfg.verbose, **ppo_kwargs
        )
        if cfg.pretrain:
            stats = behaviour_clone(model, env_fn, cfg.pretrain, seed=cfg.seed)
            write_json(out / "pretrain.json", stats)
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    formats = [
        TensorBoardOutputFormat(str(logs)),
        CSVOutputFormat(str(logs / f"progress{suffix}.csv")),
    ]
    if cfg.verbose:
        from stable_baselines3.common.logger import HumanOutputFormat

        formats.append(HumanOutputFormat(sys.stdout))
    model.set_logger(Logger(str(logs), formats))

    nav_cls, ckpt_cls, progress_cls = _callbacks()
    ckpt = ckpt_cls(cfg.checkpoint_freq, out / "checkpoints")
    remaining = cfg.timesteps - start_steps
    t0 = time.perf_counter()
    previous_term = sigterm_as_interrupt()
    try:
        if remaining > 0:
            model.learn(
                total_timesteps=remaining,
                callback=[nav_cls(n_agents), ckpt] + ([progress_cls()] if cfg.progress_bar else []),
                reset_num_timesteps=resume_path is None,
            )
    except KeyboardInterrupt:
        n = ckpt.rollout_start_timesteps if ckpt.collecting else model.num_timesteps
        path = ckpt.save(n)
        print(
            f"\ninterrupted: checkpoint written to {path}; continue with --resume {path}",
            file=sys.stderr,
        )
        monitor.close()
        raise
    finally:
        if previous_term is not None:
            signal.signal(signal.SIGTERM, previous_term)
    wall_s = time.perf_counter() - t0
    final = out / "final_model.zip"
    save_model(model, final)
    done_steps = int(model.num_timesteps) - start_steps
    info = {
        "final_model": str(final),
        "seed": cfg.seed,
        "num_timesteps": int(model.num_timesteps),
        "session_agent_steps": done_steps,
        "session_wall_s": round(wall_s, 3),
        "agent_steps_per_s": round(done_steps / wall_s, 1) if wall_s > 0 else None,
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
    monitor.close()
    return final
