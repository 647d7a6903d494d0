"""Check that an environment node keeps the contract of docs/ENV_CONTRACT.md.

    python -m clnn_ros.live.check_env python -m clnn_ros.nodes.environment --ros-args -p
    physics:=paper
    python -m clnn_ros.live.check_env python -m clnn_ros.nodes.environment --ros-args -p
    task:=gymnasium:Acrobot-v1 -p n_actions:=3
    python -m clnn_ros.live.check_env python examples/noisy_cartpole.py
    python -m clnn_ros.live.check_env --option task=point_to_goal --option n_actions=3 \
        python examples/point_to_goal.py

It starts the command in its own process as run_all would (with `--ros-args --params-file
<file> -r __ns:=/NS -r /clock:=/NS/clock` appended, the file holding every parameter an
environment takes, as a run's does: max_steps 60, the task the options (or the command's own
-p task:=... -p n_actions:=...) name, the cart-pole by default, with masses, length and gravity
other than the defaults; a pipe on stdin and CLNN_ROS_EXIT_WITH_STDIN=1), in a private
ROS_DOMAIN_ID on loopback and in a namespace of its own (default /check_env_node: a node that
uses absolute topic names fails), reads its task description (env/task) and plays trial manager
and agent against it: a trial up to the max_steps cap, a trial with the last action held until
it terminates, malformed inputs in between, a trial that takes every action, then EPISODE_END;
then it starts the command once more and closes its stdin. For each rule of the contract
(version 4) it prints PASS or FAIL with what the node did wrong; a node of an older version gets
one line that says so. The rule `physics` (the cart-pole's observations follow the core's
cart-pole with the file's physics) is advice, a WARN line, for a simulator of its own
(gymnasium, friction, a robot); --physics-from-run makes it a rule. Exit status 0 when all pass,
1 otherwise, 2 on a usage error.
Only public rclpy. The rules and the checker: clnn_ros.check_env.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import NoReturn

from ..session import rosenv  # noqa: F401  (loopback DDS discovery by default, before rclpy loads)

from ..check_env.rules import (MAX_STEPS, RULES, STRICT_PHYSICS, ParamError, checked_run,
                              command_task_options, run_summary)
from ..cli import OneLineArgumentParser
from ..graph.names import ENV_CONTRACT_VERSION, namespace_problem
from ..graph.run import write_params
from ..session.process_signals import EXIT_WITH_STDIN

__all__ = ["RULES", "main"]


def namespace_argument(text: str) -> str:
    """'/' or '/name[/name...]' (graph.names.namespace_problem)."""
    if text.strip("/") and (problem := namespace_problem(text)):
        raise argparse.ArgumentTypeError(f"{text!r} is not a ROS namespace ({problem})")
    return "/" + text.strip("/")


def main(argv: list[str] | None = None) -> NoReturn:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.live.check_env",
                                   name="check_env_node", description=__doc__.split("\n\n")[0])
    parser.add_argument("--domain-id", type=int, default=150 + os.getpid() % 80,
                        help="private ROS_DOMAIN_ID for the check (default: 150 + pid %% 80)")
    parser.add_argument("--namespace", type=namespace_argument, default="/check_env_node",
                        help="the namespace the node is started in (default /check_env_node; "
                             "/ for none)")
    parser.add_argument("--startup-timeout", type=float, default=30.0,
                        help="seconds the node gets to announce readiness once it is in the "
                             "graph, and discovery to match the checker's endpoints with the "
                             "node's")
    parser.add_argument(STRICT_PHYSICS, action="store_true",
                        help="the node simulates the run's cart-pole (its physics parameters): "
                             "a state that does not follow it is a FAIL, not a WARN")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="a value of the checker's run, as run_all's --option: the task, "
                             "e.g. --option task=my_task --option n_actions=3 (the command's "
                             "own -p task:=... and -p n_actions:=... count as these)")
    parser.add_argument("command", nargs=argparse.REMAINDER, help="the node's command line")
    args = parser.parse_args(argv)
    if not args.command:
        parser.error("give the environment node's command, e.g. python -m "
                     "clnn_ros.nodes.environment")
    if args.command[0] in ("python", "python3"):  # the interpreter (venv) of the checker
        args.command[0] = sys.executable
    if not 0 <= args.domain_id <= 232:
        parser.error("--domain-id must be 0..232")
    options = command_task_options(args.command)
    for item in args.option:
        key, equals, value = item.partition("=")
        if not equals or not key.strip():
            parser.error(f"--option expects KEY=VALUE, got {item!r}")
        options[key.strip()] = value
    try:
        # what a run's file holds for an environment (graph.run.ENVIRONMENT_GIVEN)
        values, run = checked_run(options)
    except ParamError as error:
        parser.error(str(error))
    with tempfile.TemporaryDirectory(prefix="check_env_node_") as tmp:
        params_file = write_params(Path(tmp) / "params.yaml", values)
        env = {**os.environ, "ROS_DOMAIN_ID": str(args.domain_id), EXIT_WITH_STDIN: "1",
               "ROS_AUTOMATIC_DISCOVERY_RANGE": os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE",
                                                               "LOCALHOST")}
        env.setdefault("ROS_LOG_DIR", str(Path(tmp) / "ros_log"))
        print(f"check_env_node: {' '.join(args.command)} against environment contract "
              f"version {ENV_CONTRACT_VERSION} (ROS_DOMAIN_ID {args.domain_id}, namespace "
              f"{args.namespace}, max_steps {MAX_STEPS}, {run_summary(run)})", flush=True)
        # after the arguments: --help and a usage error need no ROS
        from ..check_env.probe import Probe
        from ..check_env.scenario import run_checks
        findings = run_checks(Probe(args.command, args.namespace, args.domain_id,
                                    args.startup_timeout, params_file, env),
                              run, strict_physics=args.physics_from_run)
    ok = findings.report()
    print(f"check_env_node: {'all rules pass' if ok else 'the node breaks the contract'}",
          flush=True)
    # The verdict is out and the node stopped: the process ends here, without deleting its DDS
    # participant, which Fast DDS 2.14 can deadlock on (check_env/probe.py, Probe.session).
    sys.stderr.flush()
    os._exit(0 if ok else 1)


if __name__ == "__main__":
    main()
