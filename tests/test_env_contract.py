"""Swapping the environment node: the contract checker (contract version 4) passes the
project's environment nodes (paper cart-pole, gymnasium, a Gymnasium task) and the examples
(a noisy cart-pole, a task of their own) and fails broken ones with the right explanation, a node
of version 3 in one line (run_all too); the example task of its own learns through --env-node; a
gymnasium-node run equals the core driving gymnasium's physics; the encoder edges are
parameters; `run_all --env external` runs with an environment node started by someone else
(also in a namespace) and fails with one line when none comes (docs/ENV_CONTRACT.md)."""

from __future__ import annotations

import csv
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
import yaml

from clnn_ros import run_all
from clnn_ros.batch import run_batch
from clnn_ros.check_env.rules import (CHECKED_RUN, RUN_PHYSICS, check_physics, checked_run,
                                      command_task_options)
from clnn_ros.live.check_env import RULES
from clnn_ros.core.encoder import Encoder
from clnn_ros.core.episode import run_episode
from clnn_ros.core.physics import gym_matched_params
from clnn_ros.tasks.cartpole.gymnasium_cartpole import GymCartPole
from clnn_ros.core.params import ParamError, Params, params_from_strings
from clnn_ros.core.physics import CartPole, at_rest
from clnn_ros.graph.names import ENV_CONTRACT_VERSION, RECORDER
from clnn_ros.graph.run import ENVIRONMENT_GIVEN

from conftest import HANG_S, assert_run_equals_episode, free_domain_id, problem_lines

ROOT = Path(__file__).resolve().parents[1]
BROKEN = str(Path(__file__).with_name("broken_env_node.py"))
PY = sys.executable
# The example task of its own (examples/point_to_goal.py) as the graph runs it
POINT_TO_GOAL = ["--option", "task=point_to_goal", "--option", "n_actions=3"]
POINT_TO_GOAL_RUN = [*POINT_TO_GOAL, "--option", "state_vars=offset,velocity",
                     "--option", "variable_edges=offset:-0.5,-0.1,0.1,0.5;velocity:-0.2,0.2",
                     "--option", "reward_mapping=goal", "--option", "sigma=128",
                     "--option", "omega=128", "--max-steps", "300"]
OLDER = "the node speaks contract version 3 or older"


DOMAIN_ID = free_domain_id()
# name: (node command, checker options, lines the report must have); each check runs in its
# own namespace /check_<name> of the module's domain
CHECKS = {
    "cartpole": ([PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p", "physics:=paper"],
                 [], ["check_env_node: all rules pass"]),
    # simulators of their own: the physics rule is a WARN
    "gymnasium": ([PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p",
                   "simulator:=gymnasium"], [],
                  ["check_env_node: all rules pass", "WARN  physics: "]),
    "example": (["python", "examples/noisy_cartpole.py", "--ros-args", "-p", "force_noise:=0.2"],
                [], ["check_env_node: all rules pass", "WARN  physics: "]),
    # another task: the command's own -p task:=... is the checker's run; no physics
    "acrobot": ([PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p",
                 "task:=gymnasium:Acrobot-v1", "-p", "n_actions:=3"], [],
                ["check_env_node: all rules pass", "SKIP  physics: the task is "
                 "gymnasium:Acrobot-v1, not the cart-pole", "PASS  termination: "]),
    # a task whose trials end within the checker's cap under any actions: its truncation is said
    # not seen (the rule still holds on every observation), its termination is checked
    "invertedpendulum": ([PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p",
                          "task:=gymnasium:InvertedPendulum-v5", "-p", "n_actions:=2"], [],
                         ["check_env_node: all rules pass", "PASS  termination",
                          "PASS  truncation: "]),
    # a task of its own, written from docs/ENV_CONTRACT.md alone
    "point_to_goal": (["python", "examples/point_to_goal.py"], POINT_TO_GOAL,
                      ["check_env_node: all rules pass", "SKIP  physics: "]),
    # the same node in a run of the cart-pole: its description does not fit the run
    "task_mismatch": (["python", "examples/point_to_goal.py"], [],
                      ["FAIL  task: env/task names task 'point_to_goal', the run's is "
                       "'cartpole'", "PASS  reset", "PASS  truncation"]),
    # ignores the run's cart_mass: a FAIL that names it, with --physics-from-run
    "default_cart_mass": ([PY, BROKEN, "default_cart_mass"], ["--physics-from-run"],
                          ["FAIL  physics: ", "PASS  reset", "PASS  termination", "PASS  task"]),
    "no_reset": ([PY, BROKEN, "no_reset"], [],
                 ["FAIL  reset: successful_steps not reset at START (was 60, published 60)"]),
    # written against version 1 of the contract: the field is named as an older contract's
    "contract_v1": ([PY, BROKEN, "contract_v1"], [],
                    ["check_env_node: ", "FAIL  lockstep: publishes no env/observation"]),
    # version 3 as the graph sees it: one line
    "contract_v3": ([PY, BROKEN, "contract_v3"], [], [f"FAIL  task: {OLDER} (it publishes "
                                                      f"/check_contract_v3/cartpole/state, no "
                                                      f"env/task)"]),
    # written against version 3: its import fails
    "imports_v3": ([PY, "-c", "from clnn_ros_msgs.msg import CartPoleState"], [],
                   ["FAIL  starts: exited with status 1 before the first tick: ImportError: "]),
    "task_volatile": ([PY, BROKEN, "task_volatile"], ["--startup-timeout", "5"],
                      ["FAIL  interface: publishes env/task VOLATILE, not TRANSIENT_LOCAL",
                       "FAIL  task: no TaskDescription on /check_task_volatile/env/task"]),
    "wrong_tick": ([PY, BROKEN, "wrong_tick"], [],
                   ["FAIL  lockstep: observation tick 3 after action 1 of tick 1",
                    "PASS  reset"]),
    "several": ([PY, BROKEN, "no_exit,accept_bad_action,silent"], ["--startup-timeout", "3"],
                ["FAIL  readiness: no readiness announcement",
                 "FAIL  refusals: does not refuse action 2 (the task has 2 actions)",
                 "FAIL  episode_end: does not exit on EPISODE_END", "PASS  lockstep",
                 "PASS  successful_steps", "PASS  termination", "PASS  stdin_eof"]),
    # the example with its observation topic remapped to an absolute name: not in its namespace
    "absolute_names": (["python", "examples/noisy_cartpole.py", "--ros-args", "-r",
                        "env/observation:=/env/observation"], ["--startup-timeout", "3"],
                       ["FAIL  interface: does not publish /check_absolute_names/env/observation "
                        "(topic names must be relative); it publishes ",
                        "FAIL  readiness: no readiness announcement"]),
}
PASSING = ("cartpole", "gymnasium", "example", "acrobot", "invertedpendulum", "point_to_goal")
CHECKS_HANG_S = 600


@pytest.fixture(scope="module")
def ros_env(tmp_path_factory):
    return {**os.environ, "ROS_DOMAIN_ID": DOMAIN_ID, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "ROS_LOG_DIR": str(tmp_path_factory.mktemp("ros_log"))}


@pytest.fixture(scope="module")
def checks(ros_env, tmp_path_factory):
    """All checker runs at once, each in a namespace of its own and a domain of its own (so that
    no checker's participant is torn down while it takes in the comings and goings of the
    others'; they mostly wait on the node; about 40 s in all here). One still running after
    CHECKS_HANG_S (a bound against a hang, never a speed bound) is stopped with SIGABRT: Python's
    faulthandler writes where each of its threads stood, and that is its report (its node exits
    with its stdin)."""
    stderr = tmp_path_factory.mktemp("checkers")
    running = {}
    for name, (command, options, _) in CHECKS.items():
        with open(stderr / name, "w") as log:
            running[name] = subprocess.Popen(
                [PY, "-m", "clnn_ros.live.check_env", "--domain-id", free_domain_id(),
                 "--namespace", f"/check_{name}", *options, *command],
                cwd=ROOT, env={**ros_env, "PYTHONFAULTHANDLER": "1"}, stdout=subprocess.PIPE,
                stderr=log, text=True)
    deadline, results = time.monotonic() + CHECKS_HANG_S, {}
    for name, process in running.items():
        try:
            report = process.communicate(timeout=max(0.0, deadline - time.monotonic()))[0]
        except subprocess.TimeoutExpired:
            process.send_signal(signal.SIGABRT)
            report = f"{process.communicate()[0]}\nstill running after {CHECKS_HANG_S} s; " \
                     f"its threads:\n{(stderr / name).read_text()}"
        results[name] = report, process.returncode
    return results


@pytest.mark.ros
@pytest.mark.parametrize("name", CHECKS)
def test_checker(checks, name):
    report, status = checks[name]
    assert status == (0 if name in PASSING else 1), report
    lines = report.splitlines()
    for expected in CHECKS[name][2]:
        assert any(line.startswith(expected) for line in lines), report
    if name in PASSING:  # and the project's cart-pole passes the physics rule too
        assert sum(line.startswith("PASS  ") for line in lines) == \
            len(RULES) + (name == "cartpole"), report
    if name == "default_cart_mass":
        assert "it steps cart_mass 0.711 kg (the default), not the run's 0.9" in report, report
    if name == "contract_v1":
        assert lines[0].startswith(f"check_env_node: {PY} {BROKEN} contract_v1 against "
                                   f"environment contract version {ENV_CONTRACT_VERSION} ("), report
        assert "AttributeError: 'Observation' object has no attribute 'header' (a name of an " \
               "older contract: header (version 1); docs/ENV_CONTRACT.md, Versions)" in report
    if name == "contract_v3":  # one line says it all: no cascade of failures, no SKIP lines
        assert len(lines) == 3 and lines[-1] == "check_env_node: the node breaks the contract", \
            report
        assert f"docs/ENV_CONTRACT.md, \"Versions\", says what to change for version " \
               f"{ENV_CONTRACT_VERSION}" in lines[1], report
    if name == "imports_v3":
        assert "(a name of an older contract: CartPoleState (version 3); docs/ENV_CONTRACT.md, " \
               "Versions)" in report, report
    if name == "absolute_names":
        [interface] = [line for line in lines if line.startswith("FAIL  interface: ")]
        assert "/env/observation (clnn_ros_msgs/msg/Observation)" in interface, report
    if name == "acrobot":  # its task, from the command's own -p task:=...
        assert "task gymnasium:Acrobot-v1, 3 actions)" in lines[0], report


def test_the_checkers_run_takes_the_task_from_the_options_or_the_command():
    """The checker's run file wins over the command's own -p (as run_all's does): the task the
    command names becomes the run's; the values its harness relies on are its own."""
    command = [PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p",
               "task:=gymnasium:Acrobot-v1", "-p", "n_actions:=3", "-p", "max_steps:=500"]
    options = command_task_options(command)
    assert options == {"task": "gymnasium:Acrobot-v1", "n_actions": "3"}
    assert command_task_options(["python", "-p", "task:=x"]) == {}  # not a ROS argument
    values, run = checked_run(options)
    assert (values["task"], values["n_actions"], values["max_steps"]) == \
        ("gymnasium:Acrobot-v1", 3, 60)
    assert (run.task, run.n_actions) == ("gymnasium:Acrobot-v1", 3)
    assert set(ENVIRONMENT_GIVEN) <= set(values)
    with pytest.raises(ParamError, match="max_steps is the checker's own"):
        checked_run({"max_steps": "500"})


def steps_of(cartpole: CartPole, directions) -> list:
    """(state before, direction, state after, tick) of a cart-pole pushed with `directions`."""
    cartpole.reset(at_rest(1.0))
    steps = []
    for tick, direction in enumerate(directions, 1):
        before = cartpole.state
        cartpole.step(int(direction > 0))
        steps.append((before, direction, cartpole.state, tick))
    return steps


def test_physics_rule_names_the_ignored_parameter():
    """The checker's run is not the default cart-pole; a node that keeps a default instead of
    the run's value is told which, one that steps the run's passes."""
    assert all(getattr(CHECKED_RUN, name) != getattr(Params(), name) for name in RUN_PHYSICS)
    directions = [1, -1, -1, 1, 1, 1, -1, 1] * 3
    assert list(check_physics(steps_of(CartPole(CHECKED_RUN), directions))) == []
    for name in RUN_PHYSICS:
        kept_default = CHECKED_RUN.replace(**{name: getattr(Params(), name)})
        [problem] = check_physics(steps_of(CartPole(kept_default), directions))
        assert f"it steps {name} {getattr(Params(), name):g}" in problem, problem
    [problem] = check_physics(steps_of(CartPole(CHECKED_RUN.replace(physics="correct")),
                                       directions))
    assert "it steps physics correct, integrator semi_implicit" in problem, problem


def documented_parameters() -> dict:
    """The table of docs/ENV_CONTRACT.md's section "Parameters": {name: default run value}."""
    text = (ROOT / "docs" / "ENV_CONTRACT.md").read_text()
    section = text[text.index("## Parameters\n"):text.index("**The run's cart-pole.**")]
    rows = [line.split("|")[1:-1] for line in section.splitlines()
            if line.startswith("| `")]
    return {name.strip().strip("`"): yaml.safe_load(value.strip().strip("`"))
            for name, _type, value, _meaning in rows}


def test_the_contract_lists_every_parameter_of_the_runs_file_with_its_value():
    """An outside node written from docs/ENV_CONTRACT.md alone: the run's file of a default run
    (what run_all writes when it records) holds each parameter of the table, at the documented
    value, the physics as numbers."""
    values = {**run_all.build_parameters(run_all.parse_args([])), "extra_nodes": RECORDER}
    documented = documented_parameters()
    assert set(documented) == {*ENVIRONMENT_GIVEN, "extra_nodes"}
    assert documented == {name: values[name] for name in documented}
    # an --env-node run too, whatever its options: every value, at the run's
    values = run_all.build_parameters(run_all.parse_args(
        ["--env-node", "python my_env.py", "--physics", "correct", "--option", "cart_mass=1.5"]))
    assert set(ENVIRONMENT_GIVEN) <= set(values) and "simulator" not in values
    assert (values["physics"], values["cart_mass"], values["pole_mass"]) == \
        ("correct", 1.5, Params().pole_mass)


# Each graph of this module runs in a namespace of its own (but the one that tests the root
# namespace): what a previous graph leaves in DDS discovery for a while cannot stop the next.

@pytest.mark.ros
def test_gymnasium_node_run_equals_core_on_gymnasium_physics(ros_env, tmp_path):
    trials, max_steps, seed = 12, 300, 1
    env = ros_env
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--namespace", "gymnasium", "--env",
         "gymnasium", "--seed", str(seed),
         "--nsv", "2", "--velocity-edge", "0.3", "--trials", str(trials), "--max-steps",
         str(max_steps), "--out", str(tmp_path)], env=env, capture_output=True, text=True,
        timeout=120)
    assert result.returncode == 0, result.stderr
    p = Params(nsv=2, velocity_edge=0.3, trials=trials, max_steps=max_steps)
    core = run_episode(seed, p, env_factory=GymCartPole)
    assert_run_equals_episode(tmp_path, core)


def test_core_physics_with_gymnasium_constants_follows_gymnasium():
    """The core's own physics with gymnasium's masses (what the batch engine runs) gives the
    same trials as gymnasium's step on a short episode (long chaotic trials may drift apart)."""
    p = Params(nsv=2, velocity_edge=0.3, trials=16, max_steps=300)
    gym = run_episode(2, p, env_factory=GymCartPole)
    np.testing.assert_array_equal(run_episode(2, gym_matched_params(p)).steps, gym.steps)


def test_angle_edges_are_a_parameter():
    default = Params()
    assert default.angle_edges_deg == (-6.0, -1.0, 0.0, 1.0, 6.0) and default.n_inputs == 6
    p = params_from_strings({"angle_edges_deg": "-3, 0, 3", "nsv": "2"})
    assert p.angle_edges_deg == (-3.0, 0.0, 3.0) and p.n_inputs == 4 + 3
    assert params_from_strings({"angle_edges_deg": [-2, 2]}).angle_edges_deg == (-2.0, 2.0)
    assert params_from_strings({"angle_edges_deg": "[-2.5,2]"}).angle_edges_deg == (-2.5, 2.0)
    encoder = Encoder.from_params(p)
    assert encoder.labels()[:4] == ["pole_angle[-inf,-3)deg", "pole_angle[-3,0)deg",
                                    "pole_angle[0,3)deg", "pole_angle[3,inf)deg"]
    assert encoder.spikes((0.0, 6.0, 0.5, 0.0)).tolist() == [0, 0, 1, 0, 0, 0, 1]
    # the batch engine encodes with the same edges: equal to the core
    q = Params(angle_edges_deg="-4,-0.5,0,0.5,4", trials=24, max_steps=1500)
    assert run_batch([3], q).steps[0].tolist() == run_episode(3, q).steps.tolist()


@pytest.mark.parametrize("value, message", [
    ("1,0", "strictly increasing"), ("-1,-1", "strictly increasing"),
    ("-12,0", "inside [+]-angle_limit_deg"), ("0,15", "inside [+]-angle_limit_deg"),
    ("a,b", "numbers separated by commas"), ("", "one or more finite numbers"),
    ("nan", "one or more finite numbers"), ([True, 2], "numbers separated by commas"),
])
def test_bad_angle_edges(value, message):
    with pytest.raises(ParamError, match=message):
        params_from_strings({"angle_edges_deg": value})
    with pytest.raises(ParamError, match=message):
        Params(angle_edges_deg=value)


@pytest.mark.parametrize("args, message", [
    (["--env-node", "python x.py", "--composed"], "--env-node runs its own process"),
    (["--env-node", ""], "--env-node needs a command"),
    (["--env", "bullet"], "invalid choice: 'bullet'"),
    (["--env", "gymnasium", "--option", "tau=0.01"], "steps gymnasium's tau of 0.02 s"),
])
def test_run_all_environment_options_are_checked(ros_env, args, message):
    result = subprocess.run([PY, "-m", "clnn_ros.run_all", *args], env=ros_env,
                            capture_output=True, text=True, timeout=HANG_S)
    assert result.returncode == 2 and message in result.stderr, result.stderr


@pytest.mark.ros
def test_graph_encodes_other_angle_edges_from_parameters_only(ros_env, tmp_path):
    env = ros_env
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--namespace", "edges",
         "--option", "angle_edges_deg=-3,0,3", "--seed", "1", "--trials", "6", "--max-steps", "400",
         "--out", str(tmp_path)], env=env, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    core = run_episode(1, Params(angle_edges_deg="-3,0,3", trials=6, max_steps=400))
    assert_run_equals_episode(tmp_path, core)


@pytest.mark.ros
def test_run_all_names_a_node_of_contract_version_3_in_one_line(ros_env, tmp_path):
    """A node that publishes on cartpole/state and no env/task (version 3, as the graph sees
    it): the run ends at once, exit 1, with one line that says so, not a wait or a stall."""
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--no-record", "--namespace", "older", "--trials", "2",
         "--out", str(tmp_path), "--env-node", f"python {BROKEN} contract_v3"],
        cwd=ROOT, env=ros_env, capture_output=True, text=True, timeout=HANG_S)
    assert result.returncode == 1, result.stderr
    assert problem_lines(result.stderr) == [
        "run_all: error: the environment node speaks contract version 3 or older (it publishes "
        "cartpole/state, no env/task): docs/ENV_CONTRACT.md, \"Versions\", says what to change "
        f"for version {ENV_CONTRACT_VERSION}"], result.stderr[-3000:]


@pytest.mark.ros
def test_a_task_of_its_own_learns_through_env_node(ros_env, tmp_path):
    """examples/point_to_goal.py, a task the project does not know, through run_all --env-node
    with the run's options describing it: the run completes and its trials end at the goal
    (terminated, the task's own reason) or at the cap. How much it learns is measured in
    docs/ENV_CONTRACT.md, not asserted here (a short run)."""
    trials = 6
    result = subprocess.run(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--no-record", "--namespace", "point_to_goal",
         "--env-node", "python examples/point_to_goal.py", *POINT_TO_GOAL_RUN, "--seed", "0",
         "--trials", str(trials), "--out", str(tmp_path)],
        cwd=ROOT, env=ros_env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    with open(tmp_path / "trials.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(row["trial"]) for row in rows] == list(range(trials))
    reasons = Counter(row["end_reason"] for row in rows)
    assert set(reasons) <= {"at_goal", "max_steps"}, rows
    assert reasons["at_goal"] >= 1, rows  # seed 0 reaches the goal in trial 2 (a lockstep run)
    assert all(int(row["steps"]) <= 300 for row in rows), rows


# --- run_all --env external -------------------------------------------------------------------

WAITING = "run_all: waiting for an environment node"


class Lines:
    """A process's text stream read line by line by a thread (the pipe never fills)."""

    def __init__(self, stream):
        self.queue, self.lines = queue.Queue(), []
        self.reader = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self.reader.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.queue.put(line.rstrip("\n"))
        self.queue.put(None)

    def wait_for(self, prefix: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self.queue.get(timeout=left)
            except queue.Empty:
                break
            if line is None:
                break
            self.lines.append(line)
            if line.startswith(prefix):
                return line
        raise AssertionError(f"no line starting {prefix!r} within {timeout:g} s: {self.lines}")

    def text(self) -> str:
        self.reader.join(timeout=30)
        while not self.queue.empty():
            if (line := self.queue.get()) is not None:
                self.lines.append(line)
        return "\n".join(self.lines)


def start_external_run(ros_env, arguments: list[str], stderr_file: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [PY, "-m", "clnn_ros.run_all", "--quiet", "--env", "external", *arguments], cwd=ROOT,
        env=ros_env, stdout=subprocess.PIPE, stderr=open(stderr_file, "w"), text=True)


def end(*processes: subprocess.Popen | None) -> None:
    """After a failed assertion: nothing left running (run_all's nodes end with it)."""
    for process in processes:
        if process is not None and process.poll() is None:
            process.kill()
            process.wait(timeout=30)


@pytest.mark.ros
@pytest.mark.parametrize("namespace", [None, "robot1"])  # the root namespace, /robot1
def test_external_environment_started_separately(ros_env, tmp_path, namespace):
    """run_all --env external starts everything but the environment; the environment node,
    started by hand a few seconds later with the run's parameters (and in the run's namespace),
    completes the run, which equals the core episode."""
    seed, trials, max_steps = 1, 3, 300
    out = tmp_path / "out"
    moved = ["--namespace", namespace] if namespace else []
    run = start_external_run(ros_env, ["--seed", str(seed), "--trials", str(trials),
                                       "--max-steps", str(max_steps), "--stall-timeout", "20",
                                       "--out", str(out), *moved], tmp_path / "run_all.err")
    environment = None
    try:
        stdout = Lines(run.stdout)
        try:
            waiting = stdout.wait_for(WAITING, timeout=HANG_S)
        except AssertionError as error:
            raise AssertionError(f"{error}\n{(tmp_path / 'run_all.err').read_text()}") from None
        assert f"in namespace /{namespace or ''} " in waiting, waiting
        time.sleep(3.0)  # the rest of the graph starts meanwhile, and waits
        remaps = ["-r", f"__ns:=/{namespace}", "-r", f"/clock:=/{namespace}/clock"] \
            if namespace else []
        environment = subprocess.Popen(
            [PY, "-m", "clnn_ros.nodes.environment", "--ros-args", "-p", f"seed:={seed}",
             "-p", f"trials:={trials}", "-p", f"max_steps:={max_steps}",
             "-p", "extra_nodes:=recorder", "--log-level", "warn", *remaps],
            cwd=ROOT, env=ros_env, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        status = run.wait(timeout=180)
        stderr = (tmp_path / "run_all.err").read_text()
        assert status == 0, f"{stdout.text()}\n{stderr}"
        assert stdout.wait_for("run_all: completed:", timeout=10), stdout.text()
        # the environment ends by itself on EPISODE_END
        assert environment.wait(timeout=HANG_S) == 0, environment.stderr.read()
    finally:
        end(run, environment)
    core = run_episode(seed, Params(trials=trials, max_steps=max_steps))
    assert_run_equals_episode(out, core)
    assert (out / "bag" / "metadata.yaml").is_file()  # the recorder finished its bag


@pytest.mark.ros
def test_external_environment_that_never_comes(ros_env, tmp_path):
    """No environment node: run_all exits 1 within the stall timeout (counted once the rest of
    the graph is ready) plus a margin, with one error line that names the environment."""
    stall_timeout, margin = 3.0, 30.0
    started = time.monotonic()
    run = start_external_run(ros_env, ["--stall-timeout", str(stall_timeout), "--no-record",
                                       "--trials", "2", "--max-steps", "100",
                                       "--namespace", "nobody"], tmp_path / "run_all.err")
    try:
        Lines(run.stdout).wait_for(WAITING, timeout=HANG_S)
        waiting_at = time.monotonic()
        try:
            status = run.wait(timeout=stall_timeout + margin)
        except subprocess.TimeoutExpired:
            status = None
    finally:
        end(run)
    ended_at = time.monotonic()
    stderr = (tmp_path / "run_all.err").read_text()
    assert status is not None, \
        f"still running {ended_at - waiting_at:.1f} s after the waiting line " \
        f"({ended_at - started:.1f} s in all): {stderr}"
    assert status == 1, stderr
    errors = [line for line in stderr.splitlines() if line.startswith("run_all: error:")]
    assert len(errors) == 1, stderr
    assert "environment" in errors[0] and "/nobody" in errors[0] and \
        f"{stall_timeout:g} s" in errors[0], errors[0]


READY_LISTENER = """
import rclpy
from std_msgs.msg import String
from clnn_ros.graph import qos
from clnn_ros.session.rclpy_session import qos_profile
rclpy.init()
node = rclpy.create_node("_ready_listener")
node.create_subscription(String, "/waiting/_graph/ready", lambda m: print(m.data, flush=True),
                         qos_profile(qos.READY))
rclpy.spin(node)
"""


@pytest.mark.ros
def test_nodes_announce_again_while_the_graph_waits(ros_env, tmp_path):
    """While the graph waits (here for an environment node that is up but never announces
    itself: tests/broken_env_node.py silent), every node that is ready announces it again and
    again: a trial manager that missed the one announcement (seen once beside CPU hogs) would
    otherwise wait for good. Ready here: every node but the environment, since each of their
    endpoints has matched its peers (the environment's included)."""
    run = start_external_run(ros_env, ["--stall-timeout", "600", "--trials", "2",
                                       "--namespace", "waiting", "--out", str(tmp_path / "out")],
                             tmp_path / "run_all.err")
    listener = environment = None
    try:
        Lines(run.stdout).wait_for(WAITING, timeout=120)
        environment = subprocess.Popen(
            [PY, BROKEN, "silent", "--ros-args", "-p", "trials:=2", "-p", "extra_nodes:=recorder",
             "--log-level", "warn", "-r", "__ns:=/waiting", "-r", "/clock:=/waiting/clock"],
            cwd=ROOT, env=ros_env, stdin=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        listener = subprocess.Popen([PY, "-c", READY_LISTENER], cwd=ROOT, env=ros_env,
                                    stdout=subprocess.PIPE, text=True)
        heard, lines = Counter(), Lines(listener.stdout)
        ready = ("agent", "encoder", "recorder", "reward", "trial_manager")
        while min(heard[name] for name in ready) < 3:
            heard[lines.wait_for("", timeout=120)] += 1
        assert not set(heard) - set(ready), heard
    finally:
        for process in (listener, environment):  # SIGINT: each removes its Fast DDS files
            if process is not None:
                process.send_signal(signal.SIGINT)
                process.wait(timeout=30)
        run.send_signal(signal.SIGINT)
        try:
            run.wait(timeout=HANG_S)
        finally:
            end(run)
