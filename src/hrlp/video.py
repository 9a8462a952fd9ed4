"""Writing rollouts to video files, atomically (a killed process never leaves a half-written file)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from hrlp.atomic import atomic_path

VIDEO_SUFFIXES = (".mp4", ".gif")


def check_video_path(path: Path) -> None:
    """Raise ValueError, before any compute, if ``path`` cannot hold a video."""
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise ValueError(f"video file must end in {' or '.join(VIDEO_SUFFIXES)}, got {path.name!r}")
    parent = path.parent if str(path.parent) else Path(".")
    if parent.exists() and not parent.is_dir():
        raise ValueError(f"cannot write {path}: {parent} is not a directory")


def label_frame(frame: np.ndarray, text: str) -> np.ndarray:
    """``frame`` [H, W, 3] with ``text`` written in its top-left corner (white on a dark box)."""
    from PIL import Image, ImageDraw, ImageFont

    img = Image.fromarray(frame)
    draw = ImageDraw.Draw(img)
    font = ImageFont.load_default(size=max(10, frame.shape[0] // 18))
    box = draw.textbbox((8, 6), text, font=font)
    draw.rectangle((box[0] - 4, box[1] - 3, box[2] + 4, box[3] + 3), fill=(20, 20, 20))
    draw.text((8, 6), text, fill=(255, 255, 255), font=font)
    return np.asarray(img)


def write_video(path: Path, frames: Iterable[np.ndarray], fps: int) -> int:
    """Write RGB frames [H, W, 3] (uint8) to ``path`` (.mp4 or .gif); returns the number of frames.

    The video is written to a temporary file in the same directory and renamed into place.
    """
    import imageio.v2 as imageio

    check_video_path(path)
    n = 0
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".mp4":
            writer = imageio.get_writer(tmp, fps=fps, codec="libx264", quality=7, macro_block_size=8)
        else:
            writer = imageio.get_writer(tmp, mode="I", duration=1000 / fps, loop=0)
        with writer:
            for frame in frames:
                writer.append_data(frame)
                n += 1
    return n


def rollout_frames(
    source: str | Path, steps: int = 0, seed: int = 0, console: Console | None = None, **render_kwargs: Any
) -> tuple[Iterator[np.ndarray], int, str]:
    """Frames of a rollout (a generator), the frame rate, and what is shown: ``source`` is a task (random actions)
    or a run directory (its policy, deterministic). ``steps`` low-level steps, 0 for one episode."""
    import torch
    from rich.progress import Progress

    from hrlp.envs import TASKS, ArmEnv, make
    from hrlp.skills.macro_env import MacroEnv

    if Path(source).is_dir():
        from hrlp.train import load_trained

        trained = load_trained(Path(source))
        if trained.config.task.removeprefix("hrlp/").removesuffix("-v0") not in TASKS:
            raise ValueError(f"{source}: only runs on hrlp tasks render, this one trained {trained.config.task}")
        env = trained.make_env(render_mode="rgb_array", **render_kwargs)
        gen = torch.Generator().manual_seed(seed)
        act = lambda obs: trained.act(env, obs, gen, True)  # noqa: E731
        name = f"{trained.config.task} ({'Manager' if isinstance(env, MacroEnv) else 'flat policy'} of {source})"
    else:
        task = str(source).removeprefix("hrlp/").removesuffix("-v0")
        if task not in TASKS:
            raise ValueError(f"unknown task {source!r}; run 'hrlp tasks' to list them (only hrlp tasks render)")
        env = make(task, render_mode="rgb_array", **render_kwargs)
        rng = np.random.default_rng(seed)
        act = lambda obs: rng.uniform(-1.0, 1.0, size=9)  # noqa: E731
        name = f"{task} (random actions)"
    low: ArmEnv = env.env if isinstance(env, MacroEnv) else env.unwrapped
    n = steps or low.episode_steps
    fps = low.metadata["render_fps"]

    def frames() -> Iterator[np.ndarray]:
        obs, _ = env.reset(seed=seed)
        pending: list = []
        if isinstance(env, MacroEnv):
            env.on_substep = lambda macro: pending.append(label_frame(env.render(), macro))
        yield env.render()
        done = 0
        with Progress(console=console, transient=True, disable=console is None) as progress:
            bar = progress.add_task(f"rendering {name}", total=n)
            while done < n:
                obs, _, terminated, truncated, _ = env.step(act(obs))
                frames_now = pending[:] if pending else [env.render()]
                pending.clear()
                yield from frames_now[: n - done]
                done += len(frames_now)
                progress.update(bar, completed=min(done, n))
                if terminated or truncated:
                    obs, _ = env.reset()
        env.close()

    return frames(), fps, name
