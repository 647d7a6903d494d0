"""clnn-check-env (clnn_ros.live.check_env): an environment node checked against the contract of
docs/ENV_CONTRACT.md (version 4, any task).

    rules      the contract's rules, what was found against them, the checked run, the rules of
               a task description and of an observation (no ROS)
    probe      the checked command's process and the harness node that plays the graph
    interface  what the graph sees of the node before the first tick, its task description
    lockstep   the harness's side of the lockstep, each observation checked as it comes
    scenario   the episode played against the node, and the rules checked at its end
"""
