"""The live tools beside a running graph, each a console script:

    echo             clnn-echo: a live topic, like ros2 topic echo
    topics           clnn-topics: the live topics, like ros2 topic list -t
    save_checkpoint  clnn-save-checkpoint: ask a running agent for a checkpoint
    check_env        clnn-check-env: check an environment node against the contract (its
                     rules and its run of the node: clnn_ros.check_env)

May import graph, bag, check_env, session, cli; rclpy once their arguments are read.
"""
