"""``hrlp demo``: a Manager learns reach-and-grip (Experiment 1) by composing the shipped Reacher and Gripper skills;
``hrlp demo --robot fetch``: one learns FetchPickAndPlace by composing the Fetch skills (:mod:`hrlp.fetch.skills`).

On a fresh machine it trains for a few minutes, then evaluates the sparse success rate of
Definition 1, renders a video with the active skill on every frame, and plots the learning
curve. Running it again continues the same run (``--steps`` may grow) and redoes the outputs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from rich.console import Console

from hrlp.algos.trpo import TRPOConfig
from hrlp.config import PAPER_SETTINGS, Handover, MacroSpec, with_settings
from hrlp.fetch import check_installed
from hrlp.train import TrainConfig
from hrlp.training.sources import resolve_skills


@dataclass(frozen=True)
class DemoResult:
    """What the demo produced."""

    run_dir: Path
    success: str
    video: Path
    plot: Path


DEMO_STEPS = 1_000_000
"""The demo's training budget in low-level environment steps."""


def demo_config(steps: int = DEMO_STEPS, seed: int = 0, workers: int = 2) -> TrainConfig:
    """The demo's Manager: ReachAndGrip1 (Figure 6's task), the shipped gripper and reacher (k = 10), the Reacher
    driven for hand-over (:class:`~hrlp.skills.macro_env.Handover`), 2,000 decisions per iteration, max KL 0.02,
    parameters' initial log std -1: the ``reach-and-grip-1-handover`` preset's default cell, sampled by ``workers``
    processes (one per core on a two-core machine), with the paper's settings otherwise (:data:`PAPER_SETTINGS`: 16
    environments, exact Fisher-vector products, the baseline by 25 L-BFGS iterations on every state), as measured."""
    cfg = TrainConfig(
        task="ReachAndGrip1",
        steps=steps,
        batch_steps=2_000,
        seed=seed,
        init_log_std=-1.0,
        macro=MacroSpec(("gripper", "reacher"), k=10, handover=Handover()),
        trpo=TRPOConfig(max_kl=0.02),
    )
    return replace(with_settings(cfg, PAPER_SETTINGS), workers=workers)


#: The Fetch demo's training budget in low-level environment steps (``hrlp demo --robot fetch``).
FETCH_DEMO_STEPS = 60_000


def fetch_demo_config(steps: int = FETCH_DEMO_STEPS, seed: int = 0) -> TrainConfig:
    """The Fetch demo's Manager: the ``fetch`` preset's FetchPickAndPlace run (SAC + HER over reach, grasp and carry,
    :mod:`hrlp.fetch.skills`), in one process."""
    from hrlp.experiments.presets import PRESETS

    run = next(r for r in PRESETS["fetch"].runs if r.name == "manager-PickAndPlace")
    return replace(run.config, steps=steps, seed=seed)


#: The demos by robot: the Manager's config, what the progress lines call it, the learning curve's legend and title.
ROBOTS = {
    "arm": ("Manager on ReachAndGrip1", "Manager (gripper + reacher)", "reach-and-grip, Experiment 1"),
    "fetch": ("Manager on FetchPickAndPlace", "Manager (reach + grasp + carry)", "FetchPickAndPlace-v4"),
}


def run_demo(out_dir: Path, steps: int | None = None, seed: int = 0, episodes: int = 100, video_steps: int = 0,
             console: Console | None = None, workers: int = 2, robot: str = "arm") -> DemoResult:  # fmt: skip
    """Train (or continue) the demo Manager of ``robot`` (``arm`` or ``fetch``, :data:`ROBOTS`) in ``out_dir``,
    evaluate it, write ``demo.mp4`` (``video_steps`` low-level steps, 0 for one episode) and ``learning_curve.png``.
    ``steps`` defaults to :data:`DEMO_STEPS` (arm) or :data:`FETCH_DEMO_STEPS` (Fetch)."""
    import dataclasses

    from hrlp.checkpoint import checkpoint_exists
    from hrlp.evaluate import evaluate_run
    from hrlp.plots import plot_learning_curves
    from hrlp.train import read_run_checkpoint, train_with_progress
    from hrlp.video import rollout_frames, write_video

    console = console or Console(stderr=True)
    if robot not in ROBOTS:
        raise ValueError(f"no demo for robot {robot!r} (robots: {', '.join(ROBOTS)})")
    what, legend, title = ROBOTS[robot]
    if robot == "fetch":
        check_installed()
        cfg = fetch_demo_config(steps or FETCH_DEMO_STEPS, seed)
    else:
        cfg = demo_config(steps or DEMO_STEPS, seed, workers)
    resume = checkpoint_exists(out_dir / "checkpoint")
    if resume:
        saved = read_run_checkpoint(out_dir / "checkpoint")[2]
        if dataclasses.replace(saved, steps=cfg.steps) != cfg:
            raise ValueError(f"{out_dir} holds a different run; choose another --out-dir")
    resolve_skills(cfg.macro.skills, cfg.macro.library)  # a missing shipped skill fails here, before any compute
    train_with_progress(cfg, out_dir, resume, console, what)
    ev = evaluate_run(out_dir, episodes=episodes)
    video = out_dir / "demo.mp4"
    frames, fps, _ = rollout_frames(out_dir, steps=video_steps, seed=seed, console=console)
    write_video(video, frames, fps)
    plot = plot_learning_curves({legend: [out_dir]}, out_dir / "learning_curve.png", title=title)
    usage = ", ".join(f"{k} {v:.0%}" for k, v in (ev.macro_usage or {}).items())
    console.print(f"success rate over {episodes} evaluation episodes (95% Wilson CI): {ev.success}; decisions: {usage}")
    return DemoResult(out_dir, str(ev.success), video, plot)
