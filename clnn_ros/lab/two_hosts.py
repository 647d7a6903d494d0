"""Two hosts on one machine: the environment node in one network namespace ("robot"), the rest of
the graph in another ("brain"), joined by a veth pair with addresses of their own; DDS discovery
is restricted to that link. Runs the same episode across the link, then on one host, checks that
the results are equal and prints both throughputs (docs/MULTI_HOST.md).

    python -m clnn_ros.lab.two_hosts --seed 1 --trials 8 --max-steps 1500 --out DIR
    python -m clnn_ros.lab.two_hosts --start external --namespace robot1 ...

--start env-node (default): run_all in B starts the environment in A through `--env-node "ip
netns exec A ..."`; external: run_all in B runs `--env external`, and the environment node is
started in A separately (as on a robot, by hand or over ssh) once run_all waits for it, with the
run's parameters on its command line. --namespace NAME puts the graph under /NAME on both hosts.
Needs root (ip netns). The namespaces are named per run and removed on every exit (Ctrl-C,
SIGTERM, a failed run). DIR/one_host and DIR/two_hosts hold each run's results and bag.
Exit status: 0 equal results, 1 a run failed or the results differ, 2 bad input or no
namespaces, 130/143 interrupted.
"""

from __future__ import annotations

import json
import os
import secrets
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from ..cli import OneLineArgumentParser
from ..core.params import ParamError, params_from_strings
from ..graph.names import namespace_problem
from ..graph.run import convert_setting
from ..session.process_signals import EXIT_WITH_STDIN, catch_signals

# Addresses of the link: private to the two namespaces, so every run may use the same ones.
ADDRESSES = ("10.231.0.1", "10.231.0.2")
PREFIX_LENGTH = 30
MULTICAST = "224.0.0.0/4"  # Fast DDS discovery multicasts to 239.255.0.1: route it over the link
# How the two hosts find each other: the environment of each side, given the other's address.
DISCOVERY = {
    # multicast discovery on every interface: in these namespaces, lo and the link only
    "subnet": lambda peer: {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"},
    # no multicast at all: unicast discovery of the named peer, loopback for the host's own nodes
    "static-peers": lambda peer: {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                                  "ROS_STATIC_PEERS": peer},
}


# How the environment node in host A is started.
START_MODES = ("env-node", "external")
WAITING = "run_all: waiting for an environment node"  # run_all --env external's line
ENV_EXIT_S = 10.0  # how long the environment node gets to exit after the run


class NamespaceError(Exception):
    """A network namespace or link that could not be set up: one line."""


class Interrupted(Exception):
    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@dataclass(frozen=True)
class Link:
    namespaces: tuple[str, str]  # host A (the environment), host B (the rest)
    devices: tuple[str, str]     # each namespace's end of the veth pair
    addresses: tuple[str, str]

    def exec_prefix(self, side: int, env: dict[str, str] | None = None) -> list[str]:
        """Command prefix that runs a command on host `side` (0: A, 1: B) with extra env vars."""
        assignments = [f"{key}={value}" for key, value in (env or {}).items()]
        return ["ip", "netns", "exec", self.namespaces[side], "env", *assignments]

    def packets(self, side: int) -> tuple[int, int]:
        """(sent, received) packets of host `side`'s end of the link, from the kernel's counters."""
        shown = ip("-j", "-s", "-n", self.namespaces[side], "link", "show", self.devices[side])
        stats = json.loads(shown)[0]["stats64"]
        return stats["tx"]["packets"], stats["rx"]["packets"]


def ip(*args: str) -> str:
    result = subprocess.run(["ip", *args], capture_output=True, text=True)
    if result.returncode != 0:
        reason = (result.stderr.strip().splitlines() or [f"exit status {result.returncode}"])[-1]
        raise NamespaceError(f"ip {' '.join(args)}: {reason}")
    return result.stdout


@contextmanager
def veth_link() -> Iterator[Link]:
    """Two fresh network namespaces, each with lo and one end of a veth pair (an address, a
    multicast route, IPv6 off so that the kernel itself sends nothing on the link). On exit every
    process left in them is killed and both are removed."""
    tag = f"{os.getpid()}{secrets.token_hex(2)}"  # unique per run; device names <= 15 chars
    link = Link(namespaces=(f"clnn_{tag}_a", f"clnn_{tag}_b"), devices=(f"cv{tag}a", f"cv{tag}b"),
                addresses=ADDRESSES)
    created = []
    try:
        for namespace in link.namespaces:
            ip("netns", "add", namespace)
            created.append(namespace)
        ip("link", "add", link.devices[0], "type", "veth", "peer", "name", link.devices[1])
        for namespace, device, address in zip(link.namespaces, link.devices, link.addresses):
            ip("link", "set", device, "netns", namespace)
            ip("netns", "exec", namespace, "sysctl", "-qw",
               f"net.ipv6.conf.{device}.disable_ipv6=1")
            ip("-n", namespace, "addr", "add", f"{address}/{PREFIX_LENGTH}", "dev", device)
            ip("-n", namespace, "link", "set", "lo", "up")
            ip("-n", namespace, "link", "set", device, "up")
            ip("-n", namespace, "route", "add", MULTICAST, "dev", device)
        yield link
    finally:
        for namespace in created:
            for pid in ip("netns", "pids", namespace).split():
                try:
                    os.kill(int(pid), signal.SIGKILL)
                except ProcessLookupError:
                    pass  # it ended meanwhile
            ip("netns", "del", namespace)  # the veth pair goes with it


def run_graph(command: list[str], signals: list[int], on_line=None) -> int:
    """Run run_all to its end. A signal to this process (recorded in `signals`) is passed on and
    run_all shuts its graph down itself; then Interrupted is raised so that the namespaces go.
    on_line: called with each line of run_all's stdout (passed on to ours)."""
    if signals:
        raise Interrupted(signals[0])
    process = subprocess.Popen(command, stdout=None if on_line is None else subprocess.PIPE,
                               text=True)
    reader = None
    if on_line is not None:
        def read() -> None:
            for line in process.stdout:
                print(line, end="", flush=True)
                on_line(line)
        reader = threading.Thread(target=read, daemon=True, name="run_all-stdout")
        reader.start()
    passed_on = 0
    while process.poll() is None:
        for signum in signals[passed_on:]:
            process.send_signal(signum)
        passed_on = len(signals)
        time.sleep(0.05)
    if reader is not None:
        reader.join(timeout=5.0)
    if signals:
        raise Interrupted(signals[0])
    return process.returncode


def environment_arguments(args) -> list[str]:
    """What the environment node started by hand gets: the run's parameters that matter to it
    (the recorder that run_all adds subscribes to its state too) and the namespace."""
    arguments = ["--ros-args", "-p", f"seed:={args.seed}", "-p", f"trials:={args.trials}",
                 "-p", f"max_steps:={args.max_steps}", "-p", f"nsv:={args.nsv}",
                 "-p", "extra_nodes:=recorder", "--log-level", "warn"]
    if args.namespace:
        arguments += ["-r", f"__ns:=/{args.namespace}", "-r",
                      f"/clock:=/{args.namespace}/clock"]
    return arguments


def run_with_external_environment(command: list[str], environment: list[str],
                                  signals: list[int]) -> int:
    """run_all --env external (`command`); once it waits, `environment` starts, with a pipe on
    stdin and EXIT_WITH_STDIN as run_all gives its own nodes. After the run the node gets
    ENV_EXIT_S to exit (it does on EPISODE_END), then its stdin is closed, then it is killed."""
    started = []

    def start_when_waiting(line: str) -> None:
        if line.startswith(WAITING) and not started:
            started.append(subprocess.Popen(environment, stdin=subprocess.PIPE))
    try:
        return run_graph(command, signals, on_line=start_when_waiting)
    finally:
        for process in started:
            for stop in (lambda: None, process.stdin.close, process.kill):
                stop()
                try:
                    process.wait(timeout=ENV_EXIT_S)
                    break
                except subprocess.TimeoutExpired:
                    continue


def run_all_command(args, out: Path) -> list[str]:
    return [sys.executable, "-m", "clnn_ros.run_all", "--seed", str(args.seed),
            "--trials", str(args.trials), "--max-steps", str(args.max_steps), "--nsv",
            str(args.nsv), "--stall-timeout", str(args.stall_timeout), "--out", str(out)] + \
        (["--namespace", args.namespace] if args.namespace else [])


def compare(one_host: Path, two_hosts: Path) -> list[str]:
    """What differs between the two runs' results (empty: equal)."""
    differences = []
    if (one_host / "trials.csv").read_bytes() != (two_hosts / "trials.csv").read_bytes():
        differences.append("trials.csv")
    if not np.array_equal(np.load(one_host / "final_weights.npy"),
                          np.load(two_hosts / "final_weights.npy")):
        differences.append("final_weights.npy")
    return differences


def parse_args(argv):
    parser = OneLineArgumentParser(prog="python -m clnn_ros.lab.two_hosts", name="two_hosts",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--max-steps", type=int, default=1500)
    parser.add_argument("--nsv", type=int, default=1)
    parser.add_argument("--discovery", choices=tuple(DISCOVERY), default="subnet",
                        help="subnet: multicast on the link; static-peers: unicast to the peer only")
    parser.add_argument("--start", choices=START_MODES, default="env-node",
                        help="env-node: run_all starts the environment in host A (--env-node); "
                             "external: run_all --env external, the environment started "
                             "separately in host A")
    parser.add_argument("--namespace", metavar="NAME",
                        help="put the graph under /NAME (run_all --namespace) on both hosts")
    parser.add_argument("--stall-timeout", type=float, default=20.0,
                        help="run_all's stall timeout (s); the link adds latency to every tick")
    parser.add_argument("--out", type=Path, help="keep both runs' results here (default: a temp dir)")
    args = parser.parse_args(argv)
    if args.namespace is not None:
        if problem := namespace_problem(args.namespace):
            parser.error(f"--namespace {args.namespace!r}: {problem}")
        args.namespace = args.namespace.strip("/")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    try:  # what run_all would refuse, refused before any namespace exists
        params_from_strings({"nsv": args.nsv, "trials": args.trials, "max_steps": args.max_steps})
        convert_setting("seed", args.seed)
        convert_setting("stall_timeout_s", args.stall_timeout)
    except ParamError as error:
        print(f"two_hosts: error: {error}", file=sys.stderr)
        return 2
    signals = catch_signals()  # from here on, Ctrl-C and SIGTERM end the runs, then the namespaces
    with tempfile.TemporaryDirectory(prefix="clnn_two_hosts_") as tmp:
        out = (args.out or Path(tmp)).resolve()
        try:
            with veth_link() as link:
                return run_both(args, link, out, signals)
        except NamespaceError as error:
            print(f"two_hosts: error: {error} (network namespaces need root)", file=sys.stderr)
            return 2
        except Interrupted as interrupted:
            print("two_hosts: interrupted", file=sys.stderr)
            return 128 + interrupted.signum


def run_both(args, link: Link, out: Path, signals: list[int]) -> int:
    one_host, two_hosts = out / "one_host", out / "two_hosts"
    discovery = DISCOVERY[args.discovery]
    env_node = link.exec_prefix(0, discovery(link.addresses[1])) + \
        [sys.executable, "-m", "clnn_ros.nodes.environment"]
    run_all_b = link.exec_prefix(1, discovery(link.addresses[0])) + \
        run_all_command(args, two_hosts)
    sent_before, received_before = link.packets(0)
    if args.start == "external":
        by_hand = link.exec_prefix(0, {**discovery(link.addresses[1]), EXIT_WITH_STDIN: "1"}) + \
            [sys.executable, "-m", "clnn_ros.nodes.environment", *environment_arguments(args)]
        status = run_with_external_environment(run_all_b + ["--env", "external"], by_hand,
                                               signals)
    else:
        status = run_graph(run_all_b + ["--env-node", shlex.join(env_node)], signals)
    sent, received = (now - before for now, before in
                      zip(link.packets(0), (sent_before, received_before)))
    if status != 0:
        print(f"two_hosts: error: the two-host run failed (status {status})", file=sys.stderr)
        return 1
    # One host: the whole graph on host B's loopback.
    status = run_graph(link.exec_prefix(1, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
                       + run_all_command(args, one_host), signals)
    if status != 0:
        print(f"two_hosts: error: the one-host run failed (status {status})", file=sys.stderr)
        return 1
    differences = compare(one_host, two_hosts)
    summaries = [json.loads((run / "summary.json").read_text()) for run in (one_host, two_hosts)]
    ticks = summaries[1]["ticks"]
    rates = [summary["ticks_per_s"] for summary in summaries]
    verdict = "equal results" if not differences else "DIFFERENT " + ", ".join(differences)
    print(f"two_hosts: {verdict} ({summaries[1]['trials']} trials, {ticks} ticks); "
          f"{args.discovery} discovery, environment {args.start}"
          f"{', namespace /' + args.namespace if args.namespace else ''}; "
          f"across the link {rates[1]:.0f} ticks/s vs one host {rates[0]:.0f} ticks/s "
          f"({rates[1] / rates[0]:.2f}x); the environment's host sent {sent} and received "
          f"{received} packets on the link ({sent / ticks:.1f} / {received / ticks:.1f} per tick)",
          flush=True)
    return 1 if differences else 0


if __name__ == "__main__":
    sys.exit(main())
