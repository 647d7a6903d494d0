"""Reproduce Smith (2024): the paper's calibration numbers, the learning runs, Figures 7-15 and the
generated report docs/REPRODUCTION.md.

    python -m clnn_ros.reproduce calibrate [--out DIR]
    python -m clnn_ros.reproduce learn --nsv 1 --seeds 0-31 --trials 512 --out DIR [--option key=value]
    python -m clnn_ros.reproduce learn --state-vars pole_angle,cart_position --seeds 0-3 --out DIR
    python -m clnn_ros.reproduce sweep --param sigma=128,256 [--param ...] --nsv 1 --seeds 0-3 --trials 64 --out DIR
    python -m clnn_ros.reproduce sweep ... --ray [HEAD:PORT]    # the units on Ray (docs/CLUSTER.md)
    python -m clnn_ros.reproduce presets            # the named parameter sets for --preset NAME
    python -m clnn_ros.reproduce learn --preset gymnasium --seeds 0-31 --out DIR
    python -m clnn_ros.reproduce gym-eval DIR [--episodes 100]  # DIR's weights in gymnasium itself
    python -m clnn_ros.reproduce figures [--out DIR] [--seeds 0-31]
    python -m clnn_ros.reproduce all [--out docs]

Every run uses the numba batch engine (clnn_ros.batch) except the traces of Figures 10, 11 and 15,
which replay one trial of a learned episode with the pure core (clnn_ros.core.episode.run_trial,
learning) from the weights the batch engine had at its start. Each experiment's settings stand at
the top of its module. `learn`, `sweep` and `all` take --ray [ADDRESS]: their runs, cut into units
(a configuration x a block of seeds), run on a Ray instance of this machine or an existing cluster
(clnn_ros.reproduce.cluster), with results equal to the local run's bit for bit.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from contextlib import contextmanager
from pathlib import Path

from ..cli import OneLineArgumentParser, Terminated, sigterm_raises
from ..core.params import CARTPOLE, ParamError, Params
from ..core.presets import PRESETS
from .arguments import add_model_flags, add_task_flags, learn_params, task_values
from .calibration import calibrate, print_calibration, write_calibration
from .cluster import ClusterError
from .common import DEFAULT_SEEDS, TRIALS, executed_by, parse_seeds, stuck
from .figures import figures_markdown, make_figures
from .gym_eval import RESET_STRIDE, gym_eval, load_learn_output, print_gym_eval, write_gym_eval
from .gymnasium_physics import SELECT_SEEDS, gymnasium_markdown, gymnasium_study, write_gymnasium
from .learning import encodings, learn_run, paper_runs, print_seed_means, write_learn_outputs
from .task_learning import learn_task, summary_lines, write_task_outputs
from .task_sweep import sweep_task, write_task_sweep
from .open_choices import OPTION_SEEDS, open_choices, open_choices_markdown, write_open_choices
from .local_optima import (LOCAL_OPTIMA_SEEDS, local_optima, local_optima_markdown,
                           plot_local_optima, write_local_optima)
from .physics_modes import physics_markdown, physics_runs, write_physics
from .state_variables import (STATE_VAR_SEEDS, state_variable_runs, state_variables_markdown,
                              write_state_variables)
from .sensitivity import (SENSITIVITY_SEEDS, check_sweep_names, parse_grid,
                          sensitivity, sensitivity_markdown, sweep, sweep_configs,
                          sweep_summary_markdown, write_sensitivity, write_sweep,
                          write_sweep_report)
from .goals import REPORT_SEEDS, SELECT_SEEDS as GOAL_SELECT_SEEDS, PLAY_EPISODES, goals_study, \
    goals_markdown, plot_curves, write_goals
from .report import claims_markdown, data_files_markdown, header_markdown, write_report
from . import task_versus
from .versus import AGENTS, DEEP, FIRST_SEEDS, check_agents, run_versus, write_versus

LOCAL_RAY = "local"  # --ray without an address: a Ray instance of this machine's own


def add_cluster_flags(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ray", nargs="?", const=LOCAL_RAY, metavar="ADDRESS",
                        help="run the units (a configuration x a block of seeds) on Ray: without "
                             "ADDRESS a Ray instance of this machine (on 127.0.0.1 only), with "
                             "one the cluster whose head is at ADDRESS (HOST:PORT of its ray "
                             "start --head); needs pip install -e '.[cluster]'; docs/CLUSTER.md")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="with --ray: worker processes (default: one per CPU of the local "
                             "machine, or of the cluster)")


@contextmanager
def executor(args):
    """Within: the units run where the command's --ray says (here without it)."""
    if args.workers is not None and (args.ray is None or args.workers < 1):
        raise ValueError("--workers N goes with --ray, N at least 1")
    if args.ray is None:
        yield
        return
    from .cluster import RayExecutor
    with RayExecutor(None if args.ray == LOCAL_RAY else args.ray, args.workers) as ray_executor, \
            executed_by(ray_executor):
        yield


def log(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def cmd_calibrate(args) -> None:
    cal = calibrate()
    files = write_calibration(cal, Path(args.out))
    print_calibration(cal)
    print(f"wrote {len(files)} CSV files to {args.out}")


def cmd_learn(args) -> None:
    seeds = parse_seeds(args.seeds)
    if args.task != CARTPOLE:
        task_run = learn_task(args.task, args.actions, seeds, task_values(args), Params(),
                              Path(args.out) / "runs", args.workers or os.cpu_count() or 1)
        files = write_task_outputs(task_run, Path(args.out))
        print("\n".join(summary_lines(task_run)))
        print("wrote " + ", ".join(str(f) for f in files))
        return
    if args.actions is not None:
        raise ValueError("--actions goes with --task gymnasium:ID")
    p = learn_params(args)
    with executor(args):
        run = learn_run(f"{p.nsv}sv", f"{p.nsv} SV", seeds, p, Path(args.out) / "runs", log)
    files = write_learn_outputs(run, Path(args.out))
    print_seed_means(run)
    print("wrote " + ", ".join(str(f) for f in files))


def cmd_sweep(args) -> None:
    seeds = parse_seeds(args.seeds)
    grid = parse_grid(args.param)
    check_sweep_names(grid)
    if args.task != CARTPOLE:
        runs = sweep_task(args.task, args.actions, grid, seeds, task_values(args),
                          Path(args.out) / "runs", args.workers or os.cpu_count() or 1)
        files = write_task_sweep(runs, Path(args.out))
        print(files[-1].read_text())
        print("wrote " + ", ".join(str(f) for f in files))
        return
    if args.actions is not None:
        raise ValueError("--actions goes with --task gymnasium:ID")
    configs = sweep_configs(learn_params(args), grid)  # all valid before anything runs
    with executor(args):
        runs = sweep(configs, seeds, Path(args.out) / "runs", log)
    files = write_sweep(runs, Path(args.out))
    figure, summary = write_sweep_report(runs, args.seeds, Path(args.out))
    print(sweep_summary_markdown(runs))
    print(f"wrote {len(files)} CSV files, {figure} and {summary}")


def cmd_presets(args) -> None:
    blocks = [f"{name}: {preset.description}\n"
              + "".join(f"    {key}={value}\n" for key, value in preset.values.items())
              for name, preset in PRESETS.items()]
    print("\n".join(blocks), end="")


def cmd_gym_eval(args) -> None:
    learn = load_learn_output(Path(args.out), args.run)
    returns = gym_eval(learn, args.episodes, args.seed_offset)
    path = write_gym_eval(learn, returns, Path(args.out))
    print_gym_eval(learn, returns)
    print(f"wrote {path}")


def cmd_figures(args) -> None:
    seeds = parse_seeds(args.seeds)
    cal = calibrate()
    figs = make_figures(cal, paper_runs(seeds, cal), Path(args.out))
    print(f"wrote {len(figs.paths)} figures to {args.out}")


def cmd_all(args) -> None:
    with executor(args):
        run_all(args)


def run_all(args) -> None:
    start = time.perf_counter()
    seeds, option_seeds = parse_seeds(args.seeds), parse_seeds(args.ambiguity_seeds)
    out = Path(args.out)
    data, fig_dir = out / "data", out / "figures"
    cal = calibrate()
    files = write_calibration(cal, data)
    print_calibration(cal)
    runs = paper_runs(seeds, cal)
    for run in runs.all():
        files += write_learn_outputs(run, data)
        print(f"{run.label}: mean {run.seed_means.mean():.1f}, "
              f"stuck {stuck(run.seed_means)} of {len(seeds)}")
    physics = physics_runs(seeds, cal, runs)
    files.append(write_physics(physics, data))
    options = open_choices(option_seeds, cal)
    files += write_open_choices(options, data)
    sensitivity_seeds, optima_seeds = parse_seeds(SENSITIVITY_SEEDS), parse_seeds(LOCAL_OPTIMA_SEEDS)
    sens = sensitivity(encodings(cal), sensitivity_seeds)
    files.append(write_sensitivity(sens, data))
    optima = local_optima(optima_seeds, cal)
    files.append(write_local_optima(optima, data))
    optima_figure = plot_local_optima(optima, fig_dir / "local_optima.png")
    encodings = state_variable_runs(parse_seeds(STATE_VAR_SEEDS), cal)
    files.append(write_state_variables(encodings, data))
    figs = make_figures(cal, runs, fig_dir)
    gym = gymnasium_study(seeds, parse_seeds(SELECT_SEEDS))
    gym_files = write_gymnasium(gym, data)
    runtime = time.perf_counter() - start
    report = out / "REPRODUCTION.md"
    rel = lambda p: os.path.relpath(p, report.parent)  # noqa: E731
    path = write_report(report, [
        header_markdown(runtime, seeds, args.seeds, option_seeds, args.ambiguity_seeds,
                        float(cal.paper.fig7_steps.mean())),
        claims_markdown(cal, runs),
        figures_markdown(figs, runs, rel),
        physics_markdown(cal, physics, len(seeds)),
        open_choices_markdown(options, cal.best_edge, len(option_seeds)),
        sensitivity_markdown(sens, len(sensitivity_seeds)),
        local_optima_markdown(optima, rel(optima_figure)),
        state_variables_markdown(encodings, cal.best_edge),
        data_files_markdown(files, report.parent),
        gymnasium_markdown(gym, runs, physics, gym_files, rel)])
    print(f"wrote {path}, {len(figs.paths)} figures, {len(files)} data files "
          f"in {time.perf_counter() - start:.0f} s")


def cmd_versus(args) -> None:
    seeds = parse_seeds(args.seeds)
    agents = [a.strip() for a in (args.agents or ",".join(
        AGENTS if args.task is None else task_versus.AGENTS)).split(",") if a.strip()]
    if args.workers < 1:
        raise ValueError(f"--workers must be at least 1, got {args.workers}")
    out = Path(args.out)
    if args.task is not None:
        return versus_task(args, agents, seeds, out)
    check_agents(agents, args.stored_only)
    began = time.perf_counter()
    results = run_versus(agents, seeds, out / "data" / "versus", args.workers, args.stored_only)
    if not any(results.values()):
        raise ValueError(f"--stored-only: no agent-seed of these stored in {out / 'data'}")
    path = write_versus(results, seeds, args.seeds, out, time.perf_counter() - began)
    print(path.read_text())
    print(f"wrote {path}")


def versus_task(args, agents: list[str], seeds: list[int], out: Path) -> None:
    """versus --task: the named agents' seeds of the task run (or stored), then the report of
    every agent and task stored so far."""
    identifier = task_versus.task_id(args.task)
    task_versus.check_agents(agents, args.stored_only)
    store = out / "data" / "versus_tasks"
    by_task = {}
    for other in task_versus.TASKS:
        to_run = [] if args.stored_only or other != identifier else agents
        results = task_versus.run_task_versus(other, to_run, seeds, args.deep_seeds, store,
                                              args.workers)
        if any(results.values()):
            by_task[other] = results
    if identifier not in by_task:
        raise ValueError(f"--stored-only: no agent-seed of {identifier} stored in {store}")
    path = task_versus.write_task_versus(by_task, out)
    print(path.read_text())
    print(f"wrote {path}")


def cmd_goals(args) -> None:
    out = Path(args.out)
    study = goals_study(parse_seeds(args.report_seeds), parse_seeds(args.select_seeds),
                        args.trials or TRIALS, args.episodes, out / "data" / "goals",
                        args.report_seeds, args.select_seeds)
    files = write_goals(study, out / "data")
    report = out / "LEARNING.md"
    rel = lambda p: os.path.relpath(p, report.parent)  # noqa: E731
    figure = plot_curves(study, out / "figures" / "learning_curves.png")
    path = write_report(report, [goals_markdown(study, rel(figure), files, rel)])
    print(f"wrote {path}, {rel(figure)} and {len(files)} data files")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineArgumentParser(prog="python -m clnn_ros.reproduce",
                                   description=__doc__.split("\n\n")[0],
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    c = sub.add_parser("calibrate", help="the paper's numbers (a)-(d) under every physics mode")
    c.add_argument("--out", default="out/calibrate", help="folder for the CSV files")
    c.set_defaults(func=cmd_calibrate)

    ln = sub.add_parser("learn", help="learning episodes with the batch engine, CSV + NPZ out")
    add_model_flags(ln, "any other Params field, e.g. tie_break=index (repeatable)")
    add_task_flags(ln)
    ln.add_argument("--out", default="out/learn",
                    help="folder for learn_<n>sv.csv and weights; finished units are kept in "
                         "OUT/runs/ and not run again (an interrupted run resumes)")
    add_cluster_flags(ln)
    ln.set_defaults(func=cmd_learn)

    sw = sub.add_parser("sweep", help="a grid of parameter values, CSV per configuration, a "
                                      "summary and a figure")
    sw.add_argument("--param", action="append", default=[], metavar="NAME=V1,V2,...",
                    help="a model parameter and its values (repeatable: the grid is every "
                         "combination)")
    add_model_flags(sw, "any other Params field, fixed for the whole grid")
    add_task_flags(sw)
    sw.add_argument("--out", default="out/sweep",
                    help="folder for the CSV files, figure, summary; finished units are "
                         "kept in OUT/runs/ and not run again (an interrupted sweep resumes)")
    add_cluster_flags(sw)
    sw.set_defaults(func=cmd_sweep)

    ps = sub.add_parser("presets", help="the named parameter sets that --preset NAME takes")
    ps.set_defaults(func=cmd_presets)

    ge = sub.add_parser("gym-eval", help="a learn run's final weights, frozen, in gymnasium's "
                                         "CartPole-v1 itself; writes OUT/gym_eval.csv")
    ge.add_argument("out", metavar="OUT", help="the --out folder of clnn-reproduce learn")
    ge.add_argument("--run", metavar="NAME", help="which final_weights_NAME.npz, when OUT holds "
                                                  "several (e.g. 1sv)")
    ge.add_argument("--episodes", type=int, default=100, help="episodes per seed")
    ge.add_argument("--seed-offset", type=int, default=0,
                    help=f"episode k of seed s resets with seed {RESET_STRIDE} * s + offset + k")
    ge.set_defaults(func=cmd_gym_eval)

    fg = sub.add_parser("figures", help="Figures 7-15 as PNG (runs what they need)")
    fg.add_argument("--out", default="out/figures", help="folder for the PNG files")
    fg.add_argument("--seeds", default=DEFAULT_SEEDS, help="seeds for the learning runs")
    fg.set_defaults(func=cmd_figures)

    gl = sub.add_parser("goals", help="learning under Gymnasium's physics, out of local optima, "
                                      "the paper's re-randomization: OUT/LEARNING.md")
    gl.add_argument("--out", default="docs", help="folder for LEARNING.md, figures/ and data/ "
                                                  "(finished runs are kept in data/goals/)")
    gl.add_argument("--report-seeds", default=REPORT_SEEDS, help="seeds the report is on")
    gl.add_argument("--select-seeds", default=GOAL_SELECT_SEEDS,
                    help="seeds the choices are made on")
    gl.add_argument("--trials", type=int, help=f"trials per episode (default {TRIALS})")
    gl.add_argument("--episodes", type=int, default=PLAY_EPISODES,
                    help="frozen-weights episodes in gymnasium per seed")
    gl.set_defaults(func=cmd_goals)

    vs = sub.add_parser("versus", help="CartPole-v1 as the RL field measures agents: the RLN "
                                       "agent beside ASE/ACE, PPO and DQN: OUT/VERSUS.md")
    vs.add_argument("--seeds", default=REPORT_SEEDS,
                    help="seeds, every agent the same (" + "; ".join(
                        f"{agent}: the first {n}" for agent, n in FIRST_SEEDS.items()) + ")")
    vs.add_argument("--agents",
                    help=f"comma-separated, of: {', '.join(AGENTS)} ({', '.join(DEEP)} "
                         "need pip install -e '.[baselines]'); with --task, of rln, ppo, dqn "
                         "(default: all)")
    vs.add_argument("--task", metavar="gymnasium:ID",
                    help="another of the field's tasks instead of CartPole-v1: " + ", ".join(
                        task_versus.TASKS) + " (the report: OUT/VERSUS_TASKS.md)")
    vs.add_argument("--deep-seeds", type=int, default=8,
                    help="with --task: PPO and DQN on the first this many seeds (default 8)")
    vs.add_argument("--out", default="docs", help="folder for VERSUS.md, figures/ and data/ "
                                                  "(finished agent-seeds are kept in "
                                                  "data/versus/)")
    vs.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                    help="processes for the agents other than rln (default: one per CPU)")
    vs.add_argument("--stored-only", action="store_true",
                    help="run nothing: the report of the agent-seeds stored so far (an agent "
                         "short of its seeds is named)")
    vs.set_defaults(func=cmd_versus)

    al = sub.add_parser("all", help="everything, then writes OUT/REPRODUCTION.md")
    al.add_argument("--out", default="docs",
                    help="folder for REPRODUCTION.md, figures/ and data/")
    al.add_argument("--seeds", default=DEFAULT_SEEDS, help="seeds for the paper's runs")
    al.add_argument("--ambiguity-seeds", default=OPTION_SEEDS,
                    help="seeds for the one-option-at-a-time table")
    add_cluster_flags(al)
    al.set_defaults(func=cmd_all)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with sigterm_raises():
            args.func(args)
    except (ParamError, ValueError) as exc:
        print(f"python -m clnn_ros.reproduce {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except ClusterError as exc:
        print(f"python -m clnn_ros.reproduce {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # e.g. piped into `head`
        sys.stdout = open(os.devnull, "w")
        return 0
    except OSError as exc:
        print(f"python -m clnn_ros.reproduce {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("terminated", file=sys.stderr)
        return 128 + signal.SIGTERM
    return 0


if __name__ == "__main__":
    sys.exit(main())
