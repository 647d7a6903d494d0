"""`clnn-reproduce goals`'s outputs: the CSVs of every configuration, the learning curves (PNG)
and docs/LEARNING.md."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import STUCK_BELOW, md_table, stuck, write_csv
from .goals_measures import Outcome, Study, fig12_cells, play_rank, rank
from .goals_settings import (CANDIDATE_PLAY_EPISODES, CONVERGED, CURVE_NEAR_OPTIMUM, GYM_SOLVED,
                             GYM_TRUNCATION, GYM_WINDOW, LAST_TRIALS, LINEAR_RULE_GAINS,
                             NEAR_OPTIMUM, TWO_SV_EDGE, WORLDS)
from .gym_eval import GYM_ID

SUMMARY_HEADER = ["world", "configuration", "seeds", "mean_steps", f"seeds_below_{STUCK_BELOW}",
                  f"mean_last_{LAST_TRIALS}", f"share_converged_{CONVERGED}",
                  "share_solved_cartpole_v1", "median_trial_solved", "frozen_play_mean_return",
                  f"share_frozen_play_{GYM_SOLVED}"]


def summary_row(o: Outcome) -> list:
    means = o.steps.mean(axis=1)
    solved = o.solved_at()
    return [WORLDS[o.world][0], o.label, len(o.seeds), round(float(means.mean()), 1),
            stuck(means), round(float(o.last_means.mean()), 1), round(o.converged, 4),
            round(float(np.mean(solved > 0)), 4),
            int(np.median(solved[solved > 0])) if (solved > 0).any() else "",
            "" if o.play is None else round(float(o.play.mean()), 1),
            "" if o.play is None else round(o.play_solved, 4)]


def reported_list(study: Study) -> list[Outcome]:
    return [o for outcomes in study.reported.values() for o in outcomes]


def write_goals(study: Study, data: Path) -> list[Path]:
    preset = study.reported["gymnasium"][1]
    play_rows = ([int(s), e, round(float(a), 4), int(r)]
                 for s, returns, angles in zip(preset.seeds, preset.play, study.play_angles)
                 for e, (r, a) in enumerate(zip(returns, angles)))
    return [write_csv(data / "learning_candidates.csv", SUMMARY_HEADER,
                      [summary_row(o) for o in study.candidates]),
            write_csv(data / "learning_rerandomization_grid.csv", SUMMARY_HEADER,
                      [summary_row(o) for o in study.grid]),
            write_csv(data / "learning_reported.csv", SUMMARY_HEADER,
                      [summary_row(o) for o in reported_list(study)]),
            write_csv(data / "learning_gym_eval.csv",
                      ["seed", "episode", "start_angle_deg", "return"], play_rows)]


def thresholds(study: Study) -> dict[str, float]:
    """Per world, the mean of the last 64 trials that counts as near the optimum."""
    return {"gymnasium": CONVERGED, "paper_1sv": CURVE_NEAR_OPTIMUM * study.fig7_optimum,
            "paper_2sv": CONVERGED}


def plot_curves(study: Study, path: Path) -> Path:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(WORLDS), figsize=(5.5 * len(WORLDS), 4.5), sharey=True,
                             constrained_layout=True)
    for ax, world in zip(axes, WORLDS):
        threshold = thresholds(study)[world]
        for o in study.reported[world]:
            curve = o.rolling_converged(threshold)
            ax.plot(np.arange(LAST_TRIALS, LAST_TRIALS + len(curve)), curve,
                    label=o.label if len(o.label) < 60 else o.label[:57] + "...")
        ax.set_title(f"{WORLDS[world][0]}\nlast {LAST_TRIALS} trials' mean >= {threshold:,.0f}",
                     fontsize=9)
        ax.set_xlabel("trial")
        ax.set_ylim(0, 1.02)
        ax.legend(fontsize=6, loc="lower right")
    axes[0].set_ylabel("share of seeds")
    fig.suptitle(f"Learning curves: the share of seeds near the optimum ({study.report_spec})")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def outcome_table(outcomes: list[Outcome], with_world: bool = True) -> str:
    played = any(o.play is not None for o in outcomes)
    header = (["world"] if with_world else []) + [
        "configuration", "mean steps", f"seeds below {STUCK_BELOW:,}",
        f"last-{LAST_TRIALS} mean", f"converged (last {LAST_TRIALS} >= {CONVERGED:,})",
        "solved CartPole-v1", "median trial solved"] + (
        ["frozen play: mean return", f"frozen play: seeds >= {GYM_SOLVED}"] if played else [])
    rows = []
    for o in outcomes:
        row = summary_row(o)
        rows.append(([row[0]] if with_world else []) + [
            row[1], f"{row[3]:,.0f}", f"{row[4]} of {row[2]}", f"{row[5]:,.0f}",
            f"{row[6]:.1%}", f"{row[7]:.1%}", row[8] if row[8] != "" else "—"] + (
            ["—", "—"] if played and o.play is None else
            [f"{row[9]:.0f}", f"{row[10]:.1%}"] if played else []))
    return md_table(header, rows)


def yes(met) -> str:
    return "yes" if met else "**no**"


def goals_table(study: Study) -> str:
    gym, p1, p2 = (study.reported[w][1] for w in WORLDS)
    best_2sv = min(study.reported["paper_2sv"][1:], key=rank)
    solved = gym.solved_at()
    median = int(np.median(solved[solved > 0])) if (solved > 0).any() else "—"
    p1_mean, p2_mean = p1.steps.mean(), best_2sv.steps.mean()
    rows = [
        ["1. Gymnasium physics, preset `gymnasium`: seeds converged", ">= 90%",
         f"{gym.converged:.1%}", yes(gym.converged >= 0.9)],
        ["1. ... seeds that solve CartPole-v1 (median trial)", ">= 95%",
         f"{np.mean(solved > 0):.1%} (trial {median})", yes(np.mean(solved > 0) >= 0.95)],
        [f"1. ... frozen in `gymnasium.make(\"{GYM_ID}\")`: seeds averaging >= {GYM_SOLVED}",
         ">= 90%", f"{gym.play_solved:.1%} (mean return {gym.play.mean():.0f})",
         yes(gym.play_solved >= 0.9)],
        ["2. paper physics, 1 SV, preset `escape`: mean",
         f">= {NEAR_OPTIMUM:.0%} of {study.fig7_optimum:,.0f}",
         f"{p1_mean:,.0f} ({p1_mean / study.fig7_optimum:.1%})",
         yes(p1_mean >= NEAR_OPTIMUM * study.fig7_optimum)],
        ["2. ... seeds below 1,000", "0", str(stuck(p1.steps.mean(axis=1))),
         yes(stuck(p1.steps.mean(axis=1)) == 0)],
        [f"3. paper physics, 2 SV at {TWO_SV_EDGE:g}, best found ({best_2sv.label}): mean",
         ">= 9,000", f"{p2_mean:,.0f}", yes(p2_mean >= 9000)],
        ["3. ... seeds converged", ">= 90%", f"{best_2sv.converged:.1%}",
         yes(best_2sv.converged >= 0.9)],
    ]
    return md_table(["goal", "target", f"measured ({len(gym.seeds)} seeds)", "met"], rows)


def goals_markdown(study: Study, figure: str, files: list[Path], rel) -> str:
    gym = study.reported["gymnasium"]
    table2, preset = gym[0], gym[1]
    n = len(preset.seeds)
    span = preset.params.angle_span_deg
    inside = np.abs(study.play_angles) <= span
    paper_agent = study.candidates[0]
    best_play = min(gym, key=play_rank)
    md = ["# Learning beyond the paper: real physics, local optima, re-randomization\n",
          f"> **Generated** by `python -m clnn_ros.reproduce goals` "
          f"(clnn_ros/reproduce/goals.py). Every choice made on seeds {study.select_spec}, "
          f"reported on seeds {study.report_spec}; {preset.steps.shape[1]} trials per episode; "
          f"the batch engine (tested equal to the core and to the agent node). Do not edit by "
          f"hand.\n",
          "The neuron model and its three-factor rules are the paper's. What changes: the "
          "encoded state variables and their edges, the segments per neuron, Table 2's "
          "punishment and reward backoff (rho_minus), and the paper's own proposal, periodic "
          "re-randomization, measured below. Each is a `Params` option whose default is the "
          "paper's; the chosen sets are the presets (`clnn-reproduce presets`, `--preset` on "
          "`clnn-reproduce learn`, `sweep` and `clnn-run`).\n",
          "## Goals against measurement\n", goals_table(study) + "\n",
          f"*Converged*: a seed's last {LAST_TRIALS} trials average at least {CONVERGED:,} "
          f"steps. *Solved CartPole-v1*: gymnasium's criterion on the learning trials, each "
          f"counted as CartPole-v1 counts it (a reward per step, the failing step's too, "
          f"truncated at {GYM_TRUNCATION}): a running mean of {GYM_WINDOW} trials of at least "
          f"{GYM_SOLVED}; the median is over the seeds that solve it. *Frozen play*: the final "
          f"weights, no learning, in `gymnasium.make(\"{GYM_ID}\")` with its own random starts "
          f"(`clnn-reproduce gym-eval`).\n",
          "## The three worlds, reported\n",
          f"Per world: Table 2's parameters, the preset, the best candidate of the selection "
          f"runs (below), and the best point of the re-randomization grid; {n} seeds.\n",
          outcome_table(reported_list(study)) + "\n", f"![learning curves]({figure})\n",
          "## Goal 1: Gymnasium's CartPole-v1 physics\n",
          f"The paper's agent (the pole angle alone) learns to a mean of "
          f"{paper_agent.steps.mean():,.0f} steps under gymnasium's physics: its pole falls in "
          f"about 35 steps, and the angle alone cannot tell a pole that is falling from one "
          f"that is being caught. With the angle and its angular velocity cut at +-1 deg/s "
          f"(Table 2's parameters) {table2.converged:.0%} of the report seeds converge; the "
          f"preset `gymnasium` (36 segments per neuron, twice Table 2's punishment) converges "
          f"on {preset.converged:.1%}.\n",
          f"**Frozen play.** The preset's weights average {preset.play.mean():.0f} in "
          f"gymnasium itself; {preset.play_solved:.1%} of seeds average {GYM_SOLVED}. "
          f"The cause is the start: gymnasium draws the pole angle from +-0.05 rad "
          f"(+-2.9 deg), the protocol trains on +-{span:g} deg. Episodes that start inside "
          f"+-{span:g} deg average {preset.play[inside].mean():.0f}, the others "
          f"{preset.play[~inside].mean():.0f} ({np.mean(inside):.0%} of starts are inside; "
          f"`{rel(files[3])}` has each start angle). A pole balanced from a larger angle leaves "
          f"the cart with a velocity that an encoding without a cart input cannot see, so the "
          f"cart runs off the track (150-410 steps in the episodes we traced). The best frozen "
          f"player among the candidates, {best_play.label.removeprefix('best frozen play: ')}, "
          f"plays {best_play.play.mean():.0f} "
          f"({best_play.play_solved:.1%} of seeds at {GYM_SOLVED}) but converges on "
          f"{best_play.converged:.1%}: it keeps the pole up from every start but lets the cart "
          f"drift within a few thousand steps. No configuration we found does both.\n"]
    hand = "; ".join(f"{h.label}: mean {h.grid_mean:,.0f} over the 32 start angles, frozen play "
                     f"{h.play.mean():.0f} ({np.mean(h.play == GYM_TRUNCATION):.0%} at "
                     f"{GYM_TRUNCATION})" for h in study.hand_made)
    md.append(f"**Does a table exist that does both?** A hand-made table (each input pattern acts "
              f"as the sign of a linear rule on its interval centres, gains "
              f"{LINEAR_RULE_GAINS} for x m, x_dot m/s, theta deg, theta_dot deg/s; one segment "
              f"per pattern): {hand}. So with the cart in the encoding such a table exists; "
              f"the rules do not find it. With Table 2's reward backoff, a third or fourth "
              f"variable does not even learn to balance: rho_minus lowers, on every reward, the "
              f"weights of the inputs that were silent, so a segment unlearns the cart intervals "
              f"it did not see and must learn each cart interval anew; with rho_minus 0 they "
              f"learn, but to the cart-blind policy's level.\n")
    md.append("**How the preset was chosen** (selection seeds; frozen play "
              f"{CANDIDATE_PLAY_EPISODES} episodes a seed):\n")
    md.append(outcome_table([o for o in study.candidates if o.world == "gymnasium"], False)
              + "\n")
    md += goal_2_3_4_markdown(study, n)
    md.append("Data: " + ", ".join(f"`{rel(f)}`" for f in files) + ".\n")
    return "\n".join(md)


def goal_2_3_4_markdown(study: Study, n: int) -> list[str]:
    p1_table2, p1_preset = study.reported["paper_1sv"][:2]
    p2 = study.reported["paper_2sv"]
    best_2sv = min(p2[1:], key=rank)
    p1_mean = p1_preset.steps.mean()
    md = ["## Goal 2: paper physics, 1 SV\n",
          f"The Figure 7 weights average {study.fig7_optimum:,.0f} steps over the 32 angles. "
          f"Table 2 leaves {stuck(p1_table2.steps.mean(axis=1))} of {n} seeds below 1,000 steps. "
          f"The preset `escape` gives each neuron 12 segments (Table 2: 3 for the six angle "
          f"intervals), so that each interval can own a segment and a punished interval does "
          f"not drag the others along; twice the punishment and no reward backoff break the "
          f"balance that held seeds in trials just longer than sigma. Mean {p1_mean:,.0f} "
          f"({p1_mean / study.fig7_optimum:.1%} of the optimum), "
          f"{stuck(p1_preset.steps.mean(axis=1))} seeds below 1,000, last-{LAST_TRIALS} mean "
          f"{p1_preset.last_means.mean():,.0f}: the episode's mean includes its first trials, "
          f"before anything is learned.\n",
          outcome_table([o for o in study.candidates if o.world == "paper_1sv"], False) + "\n",
          f"## Goal 3: paper physics, 2 SV at edge {TWO_SV_EDGE:g} (the paper's open problem)\n",
          f"Not reached. The best configuration found ({best_2sv.label}) learns to a mean of "
          f"{best_2sv.steps.mean():,.0f} ({p2[0].steps.mean():,.0f} with Table 2), "
          f"{best_2sv.converged:.1%} of seeds converged. *Does a table exist?* Yes: the "
          f"Figure 12 weights reach the cap at every start angle. *Do the rules keep it?* "
          f"Yes: episodes that learn from the Figure 12 weights with that configuration "
          f"average {study.kept_fig12:,.0f} steps (selection seeds). *Do they find it?* No. "
          f"Its learned tables act unlike Figure 12's on {study.cells_from_fig12:.1f} of the "
          f"{len(fig12_cells(best_2sv))} input patterns on average; "
          f"{study.acts_as_1sv:.0%} of them, played frozen, give exactly the 1-SV optimum's "
          f"{study.fig7_optimum:,.0f} (they act on the angle alone, as Figure 7 does); of the "
          f"last {LAST_TRIALS} trials, {np.mean(best_2sv.end_status[:, -LAST_TRIALS:] == 2):.0%} "
          f"end with the cart off the track and "
          f"{np.mean(best_2sv.end_status[:, -LAST_TRIALS:] == 1):.0%} with the pole down. "
          f"Figure 12's table acts against Figure 7's in the central cells (with the cart "
          f"slow, it pushes the way Figure 7 does not), so reaching it from a table that "
          f"balances means changing several cells at once: a local optimum that neither more "
          f"punishment, exploration nor re-randomization left.\n",
          outcome_table([o for o in study.candidates if o.world == "paper_2sv"], False) + "\n",
          "## Goal 4: the paper's proposal, periodic re-randomization\n",
          "`rerandomize_every` trials (at a trial's start), each synapse is re-drawn with "
          "probability `rerandomize_fraction` to `w_base` + uniform [0, `rerandomize_range`) "
          "(`core/rln.py: rerandomize`, run by the core, the batch engine and the agent node). "
          f"The grid on the selection seeds ({study.select_spec}), each world with Table 2's "
          f"parameters:\n", outcome_table(study.grid) + "\n"]
    verdicts, helped = [], []
    for w in WORLDS:
        base, best = study.reported[w][0], study.reported[w][-1]
        verdicts.append(f"{WORLDS[w][0]}: mean {best.steps.mean():,.0f} against "
                        f"{base.steps.mean():,.0f} without, {best.converged:.1%} converged "
                        f"against {base.converged:.1%}, {stuck(best.steps.mean(axis=1))} seeds "
                        f"below {STUCK_BELOW:,} against {stuck(base.steps.mean(axis=1))}")
        if rank(best) < rank(base):
            helped.append(WORLDS[w][0])
    md.append("**Verdict**, the best grid point of each world on the report seeds: "
              + "; ".join(verdicts) + f". It beat Table 2 in {len(helped)} of {len(WORLDS)} "
              "worlds" + (f" ({'; '.join(helped)})" if helped else "") + ". Where it frees "
              "stuck seeds it does so less than the presets' segments and punishment, and a "
              "re-drawn weight of a well-learned segment falls back to w_base, a cost the good "
              "seeds pay: no preset uses it.\n")
    return md
