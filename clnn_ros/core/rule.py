"""The learning rule's constants and options as the compiled code takes them (clnn_ros.core.rln
holds the rule itself: its functions read a Rule).

A Rule is a NamedTuple of numbers, one per constant (Table 2) and per option of the rule, so
that the same tuple goes into the pure-Python core, the agent node and the numba batch engine.
"""

from __future__ import annotations

from typing import NamedTuple

from .params import TIE_BREAKS, Params

NONE, REWARD, PUNISH = 0, 1, 2  # the reward kinds, after each step
REWARD_KINDS = ("none", "reward", "punish")
ONE_HOT = {NONE: (0, 0), REWARD: (1, 0), PUNISH: (0, 1)}  # the paper's R code
KIND_OF_CODE = {code: kind for kind, code in ONE_HOT.items()}
TIE_EXACT, TIE_RANDOM = TIE_BREAKS.index("exact"), TIE_BREAKS.index("random")


class Rule(NamedTuple):
    """The constants and options of the learning rule, in the types the compiled code takes."""

    sigma: int
    omega: int
    rho_plus: float
    rho_minus: float
    punish: float
    w_max: float
    tie_break: int  # an index into TIE_BREAKS
    tag_both: bool  # tagging="both_neurons"
    e_latched: bool  # e_flag="latched"
    counter_per_trial: bool  # success_counter="per_trial"
    ceiled: bool  # inference="ceiled"
    punish_lag: int  # punish_timing: 0 "before_decay", 1 "after_decay" (ticks of decay first)
    decay_per_trial: bool  # decay_counters="per_trial"
    explore: float  # probability that the network WTA's winner is overruled
    rerandomize_every: int  # trials; 0: never
    rerandomize_fraction: float
    w_base: float
    rerandomize_range: float
    reward_on_goal: bool  # reward_mapping="goal"
    reward_shaped: bool  # reward_mapping="shaped"

    @classmethod
    def from_params(cls, p: Params) -> "Rule":
        return cls(int(p.sigma), int(p.omega), float(p.rho_plus), float(p.rho_minus),
                   float(p.punish), float(p.w_max), TIE_BREAKS.index(p.tie_break),
                   p.tagging == "both_neurons", p.e_flag == "latched",
                   p.success_counter == "per_trial", p.inference == "ceiled",
                   int(p.punish_timing == "after_decay"), p.decay_counters == "per_trial",
                   float(p.explore), int(p.rerandomize_every), float(p.rerandomize_fraction),
                   float(p.w_base), float(p.rerandomize_range), p.reward_mapping == "goal",
                   p.reward_mapping == "shaped")
