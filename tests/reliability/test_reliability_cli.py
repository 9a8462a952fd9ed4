"""The CLI's promise: every bad input ends in one line ``error: ...`` on stderr with exit code 2, within seconds, never
a traceback, a hang or a silent acceptance (docs/reliability.md, "The CLI's promise").

The inputs are the table of ``bad_cli_inputs.py``, each run as a real ``python -m hrlp`` process (four at a time) on
real files, a real trained run and real MuJoCo; ``benchmarks/reliability.py`` counts the same table."""

import re
import subprocess
import sys
import time
from collections import Counter

import pytest
from bad_cli_inputs import CASES, WAS, fill, prepare, run_all, run_case, unmet

from hrlp.algos.trpo import TRPOConfig
from hrlp.bounds import MAX_NUM_ENVS, MAX_SEED, ray_address_problem
from hrlp.config import MacroSpec, MicroAction
from hrlp.train import TrainConfig, env_factory


@pytest.fixture(scope="module")
def context(tmp_path_factory):
    return prepare(tmp_path_factory.mktemp("bad-cli"))


@pytest.fixture(scope="module")
def outcomes(context):
    return run_all(tuple(c for c in CASES if unmet(c) is None), context, workers=4)


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_a_bad_input_ends_in_one_error_line(case, outcomes):
    if (why := unmet(case)) is not None:
        pytest.skip(why)
    o = outcomes[case.name]
    assert "Traceback" not in o.stderr + o.stdout, o.stderr[-4000:]
    assert o.returncode is not None, f"no answer within {case.limit_s:g} s: {o.stderr[-2000:]}"
    assert o.returncode == 2, (o.returncode, o.stderr[-2000:], o.stdout[-500:])
    assert len(o.lines) == 1 and o.lines[0].startswith("error: "), o.stderr
    assert re.search(case.expect, o.lines[0]), o.lines[0]
    assert o.seconds < case.limit_s


def test_the_table_covers_every_command_and_every_kind_of_failure():
    assert len(CASES) >= 60 and len({c.name for c in CASES}) == len(CASES)
    commands = {c.args[0] for c in CASES} | {" ".join(c.args[:2]) for c in CASES if c.args[0] == "skills"}
    assert {"train", "train-manager", "eval", "render", "reproduce", "tables", "theory", "demo", "dagger",
            "skills build"} <= commands  # fmt: skip
    kinds = Counter(c.was for c in CASES)
    assert set(kinds) == set(WAS) and all(kinds[k] >= 5 for k in WAS), kinds


def test_errors_found_while_parsing_come_before_torch_is_imported(context):
    """A sample of the inputs rejected while the options are parsed: none imports torch (the promise's "within 2 s of
    start-up" does not wait for torch)."""
    sample = [c for c in CASES if not c.torch and unmet(c) is None][::9]
    for case in sample:
        o = run_case(case, context, python=(sys.executable, "-X", "importtime"))
        imported = {line.rsplit("|", 1)[-1].strip() for line in o.stderr.splitlines() if line.startswith("import time:")}
        assert "torch" not in imported, case.name
        errors = [line for line in o.lines if not line.startswith("import time:")]
        assert len(errors) == 1 and errors[0].startswith("error: "), (case.name, errors)


def test_help_stays_fast_and_torch_free():
    start = time.perf_counter()
    r = subprocess.run([sys.executable, "-X", "importtime", "-m", "hrlp", "--help"], capture_output=True, text=True,
                       timeout=60)  # fmt: skip
    assert r.returncode == 0 and "train-manager" in r.stdout
    assert not any(line.rstrip().endswith("| torch") for line in r.stderr.splitlines())
    assert time.perf_counter() - start < 20


def test_a_placeholder_is_filled_in_each_cases_own_directory(context):
    args, tmp = fill(CASES[0], context)
    assert tmp.is_dir() and tmp.name == CASES[0].name and not any("{" in a for a in args)


# --- the same bounds through the API: configs check them when built ---------------------------------------------------


@pytest.mark.parametrize(
    ("settings", "match"),
    [
        (dict(seed=-1), "seed must be an integer in"),
        (dict(seed=MAX_SEED + 1), "seeds are 32-bit"),
        (dict(num_envs=MAX_NUM_ENVS + 1, batch_steps=5000), "num_envs must be at most"),
        (dict(batch_steps=10**11), "batch_steps must be at most"),
        (dict(steps=10**13), "steps must be at most"),
        (dict(task_kwargs={"episode_steps": 5}), "not as a task argument"),
        (dict(batch_steps=16, num_envs=4, trpo=TRPOConfig(fisher_fraction=1e-6)), "fewer than one"),
        (dict(episode_steps=20, macro=MacroSpec(("gripper",), k=21)), r"k \(21\) is longer than an episode"),
        (dict(episode_steps=20, macro=MacroSpec((), micro=MicroAction(duration=50))), "micro-action's duration"),
    ],
)
def test_train_config_refuses_what_the_cli_refuses(settings, match):
    with pytest.raises(ValueError, match=match):
        TrainConfig(task="Reacher", **settings)


def test_env_factory_names_the_problem_before_any_compute():
    with pytest.raises(ValueError, match=r"unsupported observation space Tuple"):
        env_factory("Blackjack-v1")
    with pytest.raises(ValueError, match=r"invalid argument 'foo'.*valid arguments: render_mode, g\b"):
        env_factory("Pendulum-v1", foo=1)
    env = env_factory("Pendulum-v1", episode_steps=7)()  # a Gymnasium id's time limit
    env.reset(seed=0)
    steps = 0
    while not any(env.step(env.action_space.sample())[2:4]):
        steps += 1
    assert steps + 1 == 7
    with pytest.raises(ValueError, match="not both"):
        env_factory("Pendulum-v1", episode_steps=7, max_episode_steps=9)


def test_a_dead_ray_address_is_named_within_the_connect_timeout():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    start = time.perf_counter()
    problem = ray_address_problem(f"127.0.0.1:{port}", timeout_s=2.0)
    assert problem is not None and f"127.0.0.1:{port}" in problem and time.perf_counter() - start < 3
    assert "HOST:PORT" in ray_address_problem("nowhere")
    assert ray_address_problem("auto") is None


def test_a_ray_address_must_answer_as_ray_does_and_quickly():
    # A server that is not Ray's (an HTTP server, a listener that never answers) used to pass the check, and Ray then
    # waited ~20 s before its own multi-line error. A gRPC server (what Ray's GCS is) passes.
    import http.server
    import socket
    import threading
    from concurrent.futures import ThreadPoolExecutor

    grpc = pytest.importorskip("grpc")
    httpd = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen()
    server = grpc.server(ThreadPoolExecutor(max_workers=1))
    grpc_port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        for port, answer in ((httpd.server_port, "it answered b'"), (silent.getsockname()[1], "no answer within")):
            start = time.perf_counter()
            problem = ray_address_problem(f"127.0.0.1:{port}")
            assert problem is not None and "is not a Ray cluster" in problem and answer in problem, problem
            assert time.perf_counter() - start < 2
        assert ray_address_problem(f"127.0.0.1:{grpc_port}") is None
    finally:
        httpd.shutdown()
        silent.close()
        server.stop(None)


def test_skills_list_says_when_the_library_is_missing(tmp_path):
    # It used to list the shipped skills without a word, as if the missing library were empty.
    r = subprocess.run([sys.executable, "-m", "hrlp", "skills", "list", "--library", str(tmp_path / "nolib")],
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0 and "reacher" in r.stdout
    assert f"no library at {tmp_path / 'nolib'} yet" in r.stderr.replace("\n", "")
