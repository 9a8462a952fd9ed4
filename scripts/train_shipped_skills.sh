#!/usr/bin/env bash
# Trains the skills shipped in src/hrlp/skills/pretrained/ with hrlp's own commands, then adds
# them to that library. Each skill's manifest (`hrlp skills show NAME`) records the full training
# config, seed and step count. About 30 minutes on one core per skill here.
#
#   bash scripts/train_shipped_skills.sh [runs/skills]
set -euo pipefail
out="${1:-runs/skills}"
lib="$(python -c 'from hrlp.skills import shipped_library_root; print(shipped_library_root())')"

# Reacher: the hand to a point near the capsule (its parameter: the 3-d point).
hrlp train Reacher --steps 3000000 --batch-steps 25000 --seed 0 --run-dir "$out/reacher"

# Gripper: many close starts with the claw open around the capsule (Section 4.1), 100-step
# episodes (the Manager calls it for k = 15 steps at a time), less initial action noise, and a
# stronger reward for closing the fingers (c3 = -8 instead of -4).
hrlp train Gripper --steps 6000000 --batch-steps 25000 --episode-steps 100 --init-log-std -1 --seed 0 \
  --task-arg "start_distance=[0,0.09]" --task-arg "finger_opening=[0,1]" --task-arg c3=-8 --run-dir "$out/gripper"

hrlp skills add "$out/reacher" --name reacher --k 15 --library "$lib" --overwrite
hrlp skills add "$out/gripper" --name gripper --k 15 --library "$lib" --overwrite
