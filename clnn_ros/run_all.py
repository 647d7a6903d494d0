"""Start the whole ROS 2 graph (environment, encoder, reward, agent, trial manager), run one
episode and print a summary.

    python -m clnn_ros.run_all                       # the demonstration (about a minute)
    python -m clnn_ros.run_all --seed 1 --nsv 1 --trials 32 --out DIR
    python -m clnn_ros.run_all --composed            # all nodes in one process, one executor
    python -m clnn_ros.run_all --env gymnasium       # gymnasium's CartPole-v1 physics
    python -m clnn_ros.run_all --env mujoco          # a cart-pole simulated by MuJoCo
    python -m clnn_ros.run_all --env gymnasium:Acrobot-v1 --trials 8   # any Gymnasium task
    python -m clnn_ros.run_all --preset gymnasium    # its physics in the project's cart-pole node
    python -m clnn_ros.run_all --env-node "python examples/noisy_cartpole.py"  # your own node

Each node runs as its own process (`python -m clnn_ros.nodes.<name>`) with the same parameters
YAML; DDS discovery stays on loopback unless ROS_AUTOMATIC_DISCOVERY_RANGE says otherwise.
A recorder process writes every topic into a rosbag2 bag directory (docs/RECORDING.md):
<out>/bag/ with --out, else bags/run_<UTC time>/, or --bag DIR; --no-record: none.
Exit status: 0 done, 1 the graph failed (stall, crashed node), 2 bad input, 130 interrupted.
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import signal
import sys
import time
from pathlib import Path

import yaml

from . import bag
from .cli import OneLineArgumentParser
from .core.checkpoint import Checkpoint, load_checkpoint
from .core.params import CARTPOLE, PROTOCOLS, STATE_NAMES, ParamError
from .core.presets import PRESETS, check_preset_task
from .files import cannot_create
from .graph.names import NOT_STARTED, RECORDER, TRIAL_MANAGER, namespace_problem
from .graph.run import (DEMO, ENVIRONMENTS, OWN_TAU, RUN_SETTINGS, SIMULATORS, default_bag_path,
                        run_values)
from .core.init_weights import OPTIMAL, episode_start
from .session.process_signals import STOP_SIGNALS, catch_signals
from .session.rosenv import domain_id_problem
from .processes.run_end import report_bag
from .processes.supervise import (NODES, Supervisor, failure_of, fresh_summary, run_separate,
                                  say, start_recorder, stop_recorder, work_directory)
from .tasks import gymnasium_task
from .tasks.gymnasium_task import PREFIX

# --env-node: a command starting with one of these runs with run_all's interpreter (its venv).
PYTHON_NAMES = ("python", "python3")


def parse_args(argv):
    parser = OneLineArgumentParser(prog="python -m clnn_ros.run_all", name="run_all",
                                   description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, help=f"default {DEMO['seed']}; a checkpoint's own "
                        "when resuming")
    parser.add_argument("--trials", type=int, help=f"trials of the whole episode (default "
                        f"{DEMO['trials']}); a resume runs those after the checkpoint's")
    parser.add_argument("--nsv", type=int, help=f"1: angle; 2: angle + cart velocity (default "
                        f"{DEMO['nsv']})")
    parser.add_argument("--state-vars", metavar="NAMES",
                        help="the encoded state variables instead, in input order, e.g. "
                             "pole_angle,cart_position (of: " + ", ".join(STATE_NAMES) + ")")
    parser.add_argument("--physics", help="paper (default), correct, integration_slip or "
                        "gymnasium (CartPole-v1's step itself)")
    parser.add_argument("--protocol", choices=PROTOCOLS,
                        help="paper (default: its 32 start angles, the cart at rest) or "
                             "gymnasium (CartPole-v1's: random starts, truncated at 500 steps)")
    parser.add_argument("--velocity-edge", type=float,
                        help="with cart_velocity encoded: |dx/dt| edge in m/s (Table 1: 5)")
    parser.add_argument("--max-steps", type=int, help="successful steps that end a trial (10000)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="any other model parameter, e.g. --option tie_break=index")
    parser.add_argument("--preset", metavar="NAME",
                        help="a named set of model parameters (" + ", ".join(PRESETS) + "; "
                             "clnn-reproduce presets lists them); the params file, options and "
                             "flags override it")
    parser.add_argument("--params-file", type=Path,
                        help="a ROS 2 parameters YAML (/**: ros__parameters: ...); options win")
    parser.add_argument("--composed", action="store_true",
                        help="all nodes in one process with one executor")
    parser.add_argument("--env", type=environment_choice,
                        metavar="{" + ",".join(ENVIRONMENTS) + f",{PREFIX}ID}}",
                        help="environment node: the paper's cart-pole, gymnasium's CartPole-v1, "
                             "a cart-pole simulated by MuJoCo, any Gymnasium task (e.g. "
                             f"{PREFIX}Acrobot-v1: its first encoding, docs/TASKS.md), or "
                             "external: start none and wait (--stall-timeout) for one that "
                             "someone else starts (a robot's; docs/ENV_CONTRACT.md); default "
                             "cartpole, or a resumed checkpoint's Gymnasium task")
    parser.add_argument("--actions", metavar="VALUES", help=f"--env {PREFIX}ID with a Box action "
                        f"space: the values the agent may apply, e.g. --actions=-1,1")
    parser.add_argument("--namespace", metavar="NAME",
                        help="put every node and topic under /NAME/ (several graphs on one "
                             "ROS domain)")
    parser.add_argument("--env-node", metavar="CMD",
                        help="run this command as the environment node instead (it gets "
                             "--ros-args --params-file <the run's params> appended; it must keep "
                             "docs/ENV_CONTRACT.md; a leading 'python' is run_all's interpreter)")
    parser.add_argument("--out", type=Path, help="write trials.csv, final_weights.npy, summary.json")
    parser.add_argument("--stall-timeout", type=float,
                        help="seconds without progress before the graph is declared stalled "
                             f"(default {RUN_SETTINGS['stall_timeout_s']:g})")
    parser.add_argument("--rate", type=int, metavar="HZ",
                        help="at most HZ ticks per second of wall time (50: real time, as a "
                             "robot runs: a live view follows); default: as fast as it goes")
    parser.add_argument("--quiet", action="store_true", help="no per-trial progress lines")
    parser.add_argument("--allow-foreign-publishers", action="store_true",
                        help="a publisher on a graph topic other than the graph's node (forged "
                             "messages) is named and the run goes on, its results reported as "
                             "tainted (exit status 1); without: it ends the run")
    parser.add_argument("--bag", type=Path, help="record every topic into this bag directory "
                        "(DIR/metadata.yaml, DIR/DIR_0.mcap; an earlier bag there is replaced; "
                        "default: <out>/bag with --out, else bags/run_<UTC time>)")
    parser.add_argument("--no-record", action="store_true", help="do not record a bag")
    parser.add_argument("--init-weights", metavar="FILE|fig7|fig12",
                        help="a checkpoint .npz (e.g. <out>/checkpoint.npz): resume its episode "
                        "at its next trial, exactly, with its seed and parameters (options "
                        "must agree with them, but --trials); a weights .npy of shape (2, "
                        "segments, inputs), fig7 (1 SV) or fig12 (2 SV): a new episode from "
                        "trial 0 with those weights")
    args = parser.parse_args(argv)
    check_paths_and_commands(parser, args)
    return args


def environment_choice(text: str) -> str:
    if text in ENVIRONMENTS or (text.startswith(PREFIX) and len(text) > len(PREFIX)):
        return text
    raise argparse.ArgumentTypeError(f"invalid choice: {text!r} ({', '.join(ENVIRONMENTS)} or {PREFIX}ID)")


def check_paths_and_commands(parser: argparse.ArgumentParser, args) -> None:
    """What the nodes would find out only after they started: --out, --bag and --env-node."""
    if args.out is not None:
        if args.out.exists() and not args.out.is_dir():
            parser.error(f"--out {args.out} is a file; expected a directory (created if missing)")
        if problem := cannot_create(args.out):
            parser.error(f"--out {args.out}: {problem}")
    if args.bag is not None:
        if args.no_record:
            parser.error("--bag names the recording that --no-record turns off: give one of them")
        if args.bag.exists() and not args.bag.is_dir():
            parser.error(f"--bag {args.bag} is a file; expected a bag directory (created if "
                         f"missing)")
        if args.bag.is_dir() and (others := bag.foreign_files(args.bag)):
            parser.error(f"--bag {args.bag} holds other files than a bag ({others[0]}, ...): "
                         f"give a new directory, or an earlier bag's")
        if problem := cannot_create(args.bag):
            parser.error(f"--bag {args.bag}: {problem}")
    if args.env_node is not None:
        try:
            command = shlex.split(args.env_node)
        except ValueError as error:
            parser.error(f"--env-node {args.env_node!r}: {error}")
        if not command:
            parser.error("--env-node needs a command, e.g. \"python examples/noisy_cartpole.py\"")
        if args.composed:
            parser.error("--env-node runs its own process: not with --composed")
        script = Path(command[1]) if command[0] in PYTHON_NAMES and len(command) > 1 else None
        if Path(command[0]).is_dir():
            parser.error(f"--env-node: {command[0]} is a directory, not a program")
        if script is not None and script.is_dir() and not (script / "__main__.py").is_file():
            parser.error(f"--env-node: {script} is a directory, not a Python file (e.g. "
                         f"python {script / 'my_node.py'})")
        if command[0] not in PYTHON_NAMES and shutil.which(command[0]) is None:
            parser.error(f"--env-node: no program {command[0]!r} found")
        if args.env == "external":
            parser.error("--env-node starts the environment that --env external does not: "
                         "give one of them")
    if args.namespace is not None:
        if problem := namespace_problem(args.namespace):
            parser.error(f"--namespace {args.namespace!r}: {problem}")


def graph_namespace(args) -> str:
    """The namespace of the run's nodes and topics: "/" or "/NAME"."""
    return "/" + args.namespace.strip("/") if args.namespace else "/"


def environment_of(args, checkpoint: Checkpoint | None = None) -> str:
    """The run's --env: the one given, else the resumed checkpoint's Gymnasium task, else the
    cart-pole."""
    if args.env is not None:
        return args.env
    resumed = checkpoint.params.task if checkpoint else CARTPOLE
    return resumed if resumed.startswith(PREFIX) else "cartpole"


def build_parameters(args, checkpoint: Checkpoint | None = None) -> dict:
    """The run's values (graph.run.run_values), checked before any node starts. Defaults: the
    demonstration's, or a resumed checkpoint's seed and parameters; then the preset, the params
    file, the options and the flags; the environment: environment_of's."""
    env = environment_of(args, checkpoint)
    options = {}
    for item in args.option:
        key, sep, value = item.partition("=")
        if not sep:
            raise ParamError(f"--option expects KEY=VALUE, got {item!r}")
        try:
            options[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError:
            options[key.strip()] = value  # not YAML: the text, which the check refuses
    flags = {key: value for key, value in (
        ("seed", args.seed), ("trials", args.trials), ("nsv", args.nsv),
        ("state_vars", args.state_vars), ("physics", args.physics), ("protocol", args.protocol),
        ("velocity_edge", args.velocity_edge), ("max_steps", args.max_steps),
        ("stall_timeout_s", args.stall_timeout), ("rate_hz", args.rate)) if value is not None}
    if args.quiet:
        flags["progress"] = False
    if args.allow_foreign_publishers:
        flags["allow_foreign_publishers"] = True
    if args.init_weights:  # the nodes get a file by its full path
        flags["init_weights"] = args.init_weights if args.init_weights in OPTIMAL else \
            str(Path(args.init_weights).resolve())
    defaults = {**gymnasium_task.graph_defaults(env, DEMO, args.actions),
                **(checkpoint_values(checkpoint) if checkpoint else {})}
    if args.preset is not None and args.env_node is None and env != "external":
        check_preset_task(args.preset, env if env.startswith(PREFIX) else CARTPOLE)
    if args.env_node is None and env in SIMULATORS:
        flags["simulator"] = env
    values, params = run_values(defaults, args.preset, args.params_file, options, flags)
    if params.task != CARTPOLE and env in SIMULATORS and args.env_node is None:
        raise ParamError(f"task {params.task} needs its own environment: --env {PREFIX}ID, or "
                         f"--env-node / --env external for one of yours (--env {env}: the "
                         f"cart-pole)")
    own_tau = OWN_TAU.get(env)
    if own_tau is not None and args.env_node is None and params.tau != own_tau:
        raise ParamError(f"--env {env} steps {env}'s tau of {own_tau:g} s, got "
                         f"tau={params.tau:g}")
    if args.velocity_edge is not None and "cart_velocity" not in params.state_vars:
        raise ParamError(f"--velocity-edge needs cart_velocity among the state variables "
                         f"(this run encodes {','.join(params.state_vars)})")
    # what each node will do with init_weights, here first: one line for what does not fit
    if episode_start(values.get("init_weights", ""), values["seed"], params).resume \
            and env.startswith(PREFIX) and args.env_node is None:
        gymnasium_task.check_resumable(env)
    return values


def checkpoint_values(checkpoint: Checkpoint) -> dict:
    """A checkpoint's seed and every model parameter (the agent that saved it took them all;
    None: a value derived from the others, e.g. segments from nsv)."""
    values = {k: v for k, v in checkpoint.params.to_dict().items() if v is not None}
    return {**values, "seed": checkpoint.seed}


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        if problem := domain_id_problem():
            raise ParamError(problem)
        checkpoint = load_checkpoint(args.init_weights) \
            if args.init_weights and args.init_weights.endswith(".npz") else None
        values = build_parameters(args, checkpoint)
    except ParamError as error:  # a CheckpointError too
        print(f"run_all: error: {error}", file=sys.stderr)
        return 2
    args.env = environment_of(args, checkpoint)  # what the rest of the run reads
    namespace = graph_namespace(args)
    environment = None if args.env == "external" else args.env
    env_command = None
    if args.env_node is not None:
        env_command = shlex.split(args.env_node)  # checked by parse_args
        if env_command[0] in PYTHON_NAMES:
            env_command[0] = sys.executable
    elif environment is not None:
        env_command = [sys.executable, "-m", "clnn_ros.nodes.environment"]
    else:
        values["external_nodes"] = "environment"
    interrupted = catch_signals()
    supervisor = Supervisor()
    try:
        return run(args, values, checkpoint, supervisor, namespace, environment, env_command,
                   interrupted)
    finally:
        supervisor.close()


def run(args, values: dict, checkpoint, supervisor: Supervisor, namespace: str,
        environment: str | None, env_command: list[str] | None, interrupted: list[int]) -> int:
    began = time.time()
    with work_directory() as tmp:
        out = args.out or tmp / "out"
        values["out_dir"] = str(out.resolve())
        bag_path = None
        if not args.no_record:
            bag_path = (args.bag or default_bag_path(args.out)).resolve()
            try:
                start_recorder(supervisor, {**values, "extra_nodes": ""}, bag_path, tmp,
                               namespace, args.env_node or args.env)
            except OSError as error:
                print(f"run_all: error: cannot write the bag {bag_path}: {error}", file=sys.stderr)
                return 2
            values["extra_nodes"] = RECORDER
            print(f"run_all: recording to {bag_path}", flush=True)
        announce(args, values, checkpoint, namespace)
        if environment is None and args.env_node is None:
            print(f"run_all: waiting for an environment node in namespace {namespace} (at most "
                  f"{values.get('stall_timeout_s', RUN_SETTINGS['stall_timeout_s']):g} s once the "
                  f"rest is ready)", flush=True)
        error, recorder_forced = None, False
        if args.composed:
            from .processes.composed import run_composed  # loads rclpy and the nodes
            status, reason = run_composed(values, environment is not None, namespace,
                                          interrupted)
        else:
            status, error = run_separate(supervisor, values, tmp, env_command,
                                         namespace, interrupted, began, bag_path)
            reason = supervisor.children[TRIAL_MANAGER].own_error()
        if bag_path is not None:
            recorder = supervisor.children[RECORDER]
            if error is None and not interrupted and recorder.returncode not in (None, 0):
                error = failure_of(recorder, bag_path)  # it failed first: the graph then stopped
            episode_ended = status in (0, 1) and error is None
            recorder_forced = stop_recorder(supervisor, episode_ended)
            # Told to stop while still starting (before its handler was set), it dies of the
            # SIGTERM: as told, nothing recorded.
            stopped_as_told = (0, 128 + signal.SIGINT) + \
                (() if episode_ended else (-signal.SIGTERM,))
            if error is None and not interrupted and not recorder_forced and \
                    recorder.returncode not in stopped_as_told:
                error = failure_of(recorder, bag_path)
        summary = fresh_summary(out, began)
    supervisor.close()  # the children's last lines, passed on before the verdict
    lacking = "" if bag_path is None else report_bag(
        bag_path, status, summary, recorder_forced,
        supervisor.children[RECORDER].stopped_s if RECORDER in supervisor.children else 0.0)
    if summary and error is None and status != NOT_STARTED:  # the error line says why not
        mean = summary["mean_steps"]
        print(f"run_all: {summary['exit_reason']}: {summary['trials']} trials, mean steps "
              f"{mean if mean is None else round(mean, 1)}, {summary['ticks']} ticks, "
              f"{summary['ticks_per_s'] or 0.0:.0f} ticks/s"
              + (f"; results in {args.out}" if args.out else ""), flush=True)
    # The verdict is the last line, what the bag lacks on it (issue 47)
    if error is None and status in (128 + signum for signum in STOP_SIGNALS):
        say("run_all: interrupted")
        return status
    if error is None and status == 0 and summary.get("exit_reason") == "interrupted":
        error = "the trial manager was stopped by a signal from outside run_all"
    elif error is None and status != 0:
        error = summary.get("exit_reason") or reason or \
            f"the trial manager exited with status {status}"
    if error is not None:
        say(f"run_all: error: {error}" + (f"; {lacking}" if lacking else ""))
        return 1
    if lacking:
        say(f"run_all: warning: {lacking}")
    return 0


def announce(args, values: dict, checkpoint, namespace: str) -> None:
    mode = "composed (one process)" if args.composed else f"{len(NODES)} processes"
    encoded = f"{values['nsv']} SV" if "state_vars" not in values else \
        "state " + ",".join(values["state_vars"])
    print(f"run_all: seed {values['seed']}, {values['trials']} trials, {encoded}, "
          f"{mode}" + (f", environment: {args.env_node or args.env}"
                       if args.env_node or args.env != "cartpole" else "")
          + (f", preset {args.preset}" if args.preset else "")
          + (f", namespace {namespace}" if namespace != "/" else ""), flush=True)
    if checkpoint is not None:
        print(f"run_all: resuming {args.init_weights} at trial {checkpoint.next_trial + 1} "
              f"of {values['trials']}"
              + (f" (saved at its step {checkpoint.trial_step}: the trial restarts from its "
                 f"beginning with the weights of that moment)" if checkpoint.trial_step
                 else ""), flush=True)
    elif args.init_weights:
        print(f"run_all: new episode with the weights {args.init_weights}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
