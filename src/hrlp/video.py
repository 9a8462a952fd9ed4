"""Writing rollouts to video files, atomically (a killed process never leaves a half-written file)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, SupportsFloat

import gymnasium as gym
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


class RenderingError(ValueError):
    """MuJoCo cannot render here: its OpenGL backend (``MUJOCO_GL``) is missing a library or a display."""


#: The Debian packages that provide each of MuJoCo's OpenGL backends (``MUJOCO_GL``).
GL_PACKAGES = {
    "egl": "libegl1 with a GPU driver's EGL or Mesa's libegl-mesa0",
    "osmesa": "libosmesa6",
    "glfw": "libglfw3 and a display",
}


def _gl_problem(backend: str, error: BaseException) -> str:
    """One line for a failed OpenGL context of ``backend``: the package that is missing, or what else to use."""
    import os

    detail = " ".join(str(error).split())[:160] or type(error).__name__
    if isinstance(error, ImportError):
        if "PYOPENGL_PLATFORM" in detail:
            return (f"MUJOCO_GL={backend} and PYOPENGL_PLATFORM={os.environ.get('PYOPENGL_PLATFORM')} disagree: unset "
                    f"PYOPENGL_PLATFORM (MuJoCo sets it) or set it to {backend}")  # fmt: skip
        return (f"MuJoCo's {backend or 'glfw'} rendering backend cannot be imported ({detail}): pip install pyopengl"
                f"{' glfw' if backend in ('', 'glfw') else ''}")  # fmt: skip
    other = "MUJOCO_GL=egl (Debian: libegl1) or MUJOCO_GL=osmesa (Debian: libosmesa6)"
    if backend == "osmesa":
        return ("MUJOCO_GL=osmesa: no OSMesa library (libOSMesa.so) could be loaded: install the Debian package "
                "libosmesa6 (apt-get install libosmesa6), or use MUJOCO_GL=egl")  # fmt: skip
    if backend == "egl":
        return (f"MUJOCO_GL=egl: no EGL context could be created ({detail}): install the Debian package "
                f"{GL_PACKAGES['egl']}, or use MUJOCO_GL=osmesa (Debian: libosmesa6)")  # fmt: skip
    display = "DISPLAY is not set" if not os.environ.get("DISPLAY") else f"DISPLAY={os.environ['DISPLAY']}"
    return (f"MuJoCo renders through GLFW{' (MUJOCO_GL unset)' if not backend else ''}, which needs a display ({display}; "
            f"{detail}); to render off-screen set {other}")  # fmt: skip


_GL_MODULES = ("mujoco/osmesa", "mujoco/egl", "mujoco/glfw", "mujoco/gl_context", "mujoco/rendering/classic/gl_context",
               "mujoco/rendering/classic/renderer", "OpenGL/")  # fmt: skip


def gl_failure_line(error: BaseException) -> str | None:
    """The one line for an error raised while MuJoCo set up its OpenGL backend (at ``import mujoco`` when
    ``MUJOCO_GL`` is egl or osmesa and its library is missing), or None for any other error."""
    import os

    tb = error.__traceback__
    while tb is not None:
        if any(m in tb.tb_frame.f_code.co_filename.replace(os.sep, "/") for m in _GL_MODULES):
            return _gl_problem(os.environ.get("MUJOCO_GL", "").strip().lower(), error)
        tb = tb.tb_next
    return None


def check_rendering(width: int, height: int) -> None:
    """Raise, before any compute, :class:`RenderingError` if MuJoCo cannot render here (naming the Debian package of
    the ``MUJOCO_GL`` backend that is missing), or ValueError if a ``width`` x ``height`` frame does not fit the
    model's off-screen framebuffer. Costs one small OpenGL context (tens of milliseconds)."""
    import os

    import mujoco

    from hrlp.arm.physics import model_xml
    from hrlp.mjcompat import open_renderer

    model = mujoco.MjModel.from_xml_string(model_xml())
    max_w, max_h = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
    for flag, value, high in (("--width", width, max_w), ("--height", height, max_h)):
        if not 16 <= value <= high:
            raise ValueError(f"{flag} must be in [16, {high}], got {value}: frames are rendered in the model's "
                             f"off-screen framebuffer of {max_w}x{max_h} pixels")  # fmt: skip
    import warnings

    backend = os.environ.get("MUJOCO_GL", "").strip().lower()
    try:
        with warnings.catch_warnings():  # GLFW warns before it fails: the one line below says it all
            warnings.simplefilter("ignore")
            renderer = open_renderer(model, 16, 16)
    except Exception as e:  # a system library or a display missing, however the backend says so
        raise RenderingError(_gl_problem(backend, e)) from None
    renderer.close()


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


class _FrameRecorder(gym.Wrapper):
    """Renders a frame after every step, kept in ``frames`` until taken: a flat environment's frames, drawn as the
    step ends (before the vector environment resets an episode that ended), as a MacroEnv's ``on_substep`` does."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.frames: list[np.ndarray] = []

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        out = self.env.step(action)
        self.frames.append(self.env.render())  # type: ignore[arg-type]
        return out


def rollout_frames(
    source: str | Path, steps: int = 0, seed: int = 0, console: Console | None = None, **render_kwargs: Any
) -> tuple[Iterator[np.ndarray], int, str]:
    """Frames of a rollout (a generator), the frame rate, and what is shown: ``source`` is a task (random actions)
    or a run directory (its policy, deterministic). ``steps`` low-level steps, 0 for one episode.

    The rollout goes through the same :class:`~hrlp.envs.vector.VectorEnv` protocol as training and evaluation (one
    environment: :func:`hrlp.rollout.vector_env`), with the policy's flat action rows; the frames are drawn after
    every low-level step (a Manager's labelled with the macro-action running)."""
    import torch
    from rich.progress import Progress

    from hrlp.arm import TASKS, ArmEnv, make
    from hrlp.rollout import vector_env
    from hrlp.skills.macro_env import MacroEnv

    if Path(source).is_dir():
        from hrlp.train import load_trained

        trained = load_trained(Path(source))
        gym_run = trained.config.task.removeprefix("hrlp/").removesuffix("-v0") not in TASKS
        # A Gymnasium environment draws its own frames (its size and camera are its own: render_kwargs are the arm's).
        env = trained.make_env(render_mode="rgb_array") if gym_run else trained.make_env(render_mode="rgb_array",
                                                                                          **render_kwargs)  # fmt: skip
        gen = torch.Generator().manual_seed(seed)
        act = lambda obs: trained.act_rows(obs, gen, True)  # noqa: E731
        name = f"{trained.config.task} ({'Manager' if isinstance(env, MacroEnv) else 'flat policy'} of {source})"
    else:
        task = str(source).removeprefix("hrlp/").removesuffix("-v0")
        if task not in TASKS:
            raise ValueError(f"unknown task {source!r}; run 'hrlp tasks' to list them (only hrlp tasks render)")
        env = make(task, render_mode="rgb_array", **render_kwargs)
        rng = np.random.default_rng(seed)
        act = lambda obs: rng.uniform(-1.0, 1.0, size=(1, 9))  # noqa: E731
        name = f"{task} (random actions)"
    low = env.env if isinstance(env, MacroEnv) else env.unwrapped
    if isinstance(low, ArmEnv):
        n, fps = steps or low.episode_steps, int(low.metadata["render_fps"])
    else:  # a Gymnasium run (flat or a Manager's): its time limit (else 1,000 steps) and its frame rate (else 30)
        own = env.env if isinstance(env, MacroEnv) else env
        modes = own.metadata.get("render_modes", [])
        if "rgb_array" not in modes:
            env.close()
            raise ValueError(f"{source}: {own.spec.id if own.spec else 'its environment'} does not draw frames "
                             f"(render modes {modes}; a video needs 'rgb_array')")  # fmt: skip
        n = steps or (own.spec.max_episode_steps if own.spec and own.spec.max_episode_steps else 1000)
        fps = int(own.metadata.get("render_fps") or 30)

    def frames() -> Iterator[np.ndarray]:
        if isinstance(env, MacroEnv):
            pending: list[np.ndarray] = []
            env.on_substep = lambda macro: pending.append(label_frame(env.render(), macro))
            vec = vector_env([env])
        else:
            recorder = _FrameRecorder(env)
            pending = recorder.frames
            vec = vector_env([recorder])
        obs = vec.reset(seed=seed)
        yield env.render()
        done = 0
        with Progress(console=console, transient=True, disable=console is None) as progress:
            bar = progress.add_task(f"rendering {name}", total=n)
            while done < n:
                obs = vec.step(act(obs)).obs  # the next episode's first observation where one ended
                frames_now = pending[:]
                pending.clear()
                yield from frames_now[: n - done]
                done += len(frames_now)
                progress.update(bar, completed=min(done, n))
        vec.close()

    return frames(), fps, name
