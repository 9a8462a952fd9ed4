"""Training, flat or Manager: the one loop (collect, advantages, fit the baseline, policy step, log) and the run
around it, one module per job in :mod:`hrlp.training`:

- :mod:`hrlp.config`: the settings (:class:`TrainConfig` and its records);
- :mod:`hrlp.training.environments`: building a run's environments (one, or N at once for the batched backend);
- :mod:`hrlp.training.loading`: reading a run's checkpoint and its policy ready to act;
- :mod:`hrlp.training.logs`: ``progress.csv``, TensorBoard and the progress lines;
- :mod:`hrlp.training.loop`: :class:`Trainer` (one iteration of the paper's algorithm) and :func:`train`.

Flat policies (any hrlp task, any Gymnasium id with a Box, Discrete or parameterised
``Tuple(Discrete(n), Box, ...)`` action space) and Managers (an hrlp task wrapped in a
:class:`~hrlp.skills.macro_env.MacroEnv` of frozen skills) go through the same loop; every batch
carries the per-decision discount GAE applies (gamma for a flat step, gamma^tau for a Manager's decision).
Everything is importable from here, as before the split.
"""

from __future__ import annotations

from hrlp.checkpoint import RUN_META_KEYS, read_run_checkpoint
from hrlp.config import ALGOS, TrainConfig  # torch-free (for `hrlp --help`)
from hrlp.training.environments import (
    TRAINING_ONLY_TASK_ARGS,
    action_units,
    batched_factory,
    check_skill_hashes,
    env_factory,
    resolve_config,
    run_factory,
)
from hrlp.training.loading import (
    TrainedPolicy,
    check_action_units,
    load_policy,
    load_trained,
    warm_start,
)
from hrlp.training.logs import (
    RunLogger,
    progress_line,
    truncate_log,
    update_stat,
)
from hrlp.training.loop import (
    REJECTED_STEPS_WARNING,
    RunSummary,
    StepPlan,
    Trainer,
    TrainingWarning,
    budget_spent,
    config_differences,
    plan_steps,
    rejected_steps_message,
    train,
    train_with_progress,
)

__all__ = [
    "ALGOS",
    "REJECTED_STEPS_WARNING",
    "RUN_META_KEYS",
    "TRAINING_ONLY_TASK_ARGS",
    "RunLogger",
    "RunSummary",
    "StepPlan",
    "TrainConfig",
    "TrainedPolicy",
    "Trainer",
    "TrainingWarning",
    "action_units",
    "batched_factory",
    "budget_spent",
    "check_action_units",
    "check_skill_hashes",
    "config_differences",
    "env_factory",
    "load_policy",
    "load_trained",
    "plan_steps",
    "progress_line",
    "read_run_checkpoint",
    "rejected_steps_message",
    "resolve_config",
    "run_factory",
    "train",
    "train_with_progress",
    "truncate_log",
    "update_stat",
    "warm_start",
]
