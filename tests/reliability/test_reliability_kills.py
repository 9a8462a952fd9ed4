"""A training process killed (SIGKILL, a real process) around a checkpoint save loses no iteration of its log: the
row of an iteration is written before its checkpoint, a resume drops rows past the checkpoint and writes them again,
and a run killed before its first checkpoint starts over with an empty log (docs/reliability.md, "Figures";
``benchmarks/reliability.py`` kills at every step of the save protocol and at random moments)."""

import csv
from concurrent.futures import ThreadPoolExecutor

import pytest
from save_protocol import check_and_resume, kill_config, protocol_steps, run_child

from hrlp.checkpoint import load_checkpoint
from hrlp.train import train

ITERATIONS = 3
KILLS = {  # name: (save, the step just before which the process kills itself)
    "between the checkpoint and the next iteration": (2, "after the save"),
    "before the checkpoint, after the log row": (2, "create the temporary directory"),
    "during the first checkpoint": (1, "rename the new one into place"),
}


@pytest.fixture(scope="module")
def killed(tmp_path_factory):
    root = tmp_path_factory.mktemp("kills")
    steps = protocol_steps(root, (1, 2), ITERATIONS)
    for _ in train(kill_config(ITERATIONS), root / "reference"):
        pass
    reference = load_checkpoint(root / "reference" / "checkpoint")[0]

    def kill(name):
        save, label = KILLS[name]
        return run_child(root / name.replace(" ", "-"), ITERATIONS, save, steps[save].index(label) + 1)

    with ThreadPoolExecutor(3) as pool:
        children = dict(zip(KILLS, pool.map(kill, KILLS), strict=True))
    return root, reference, children


@pytest.mark.parametrize("name", sorted(KILLS))
def test_a_run_killed_around_a_save_resumes_exactly_and_logs_every_iteration_once(name, killed):
    root, reference, children = killed
    run_dir = root / name.replace(" ", "-")
    assert children[name].killed
    with (run_dir / "progress.csv").open() as f:
        logged = [int(r["iteration"]) for r in csv.DictReader(f)]
    save = KILLS[name][0]
    assert logged in ([*range(1, save)], [*range(1, save + 1)]), logged  # what the kill left
    result = check_and_resume(run_dir, ITERATIONS, reference)
    assert not result["corrupt"] and not result["failed_resume"], result["problem"]
    assert result["bit_exact"] and result["log_ok"], result["problem"]
