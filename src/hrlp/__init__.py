"""hrlp: Hierarchical Reinforcement Learning with Parameters.

A Manager picks one of several frozen, parameterised skills and the skill's parameters; the skill
then runs for k low-level steps. The Manager is trained with TRPO under the hierarchical KL of
Lemma 1 (Klimek et al., "Hierarchical Reinforcement Learning with Parameters", CoRL 2017).
"""

import os

# Off-screen rendering on machines without a display: MuJoCo reads MUJOCO_GL when it is first
# imported, so it is set here, before any submodule imports mujoco. A user's own choice wins.
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"
