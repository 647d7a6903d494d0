"""The graph's contract, in one place and without ROS: what the nodes, run_all, the launch file,
the recorder and the offline tools agree on. Nothing here imports rclpy, so offline tools read it
without loading ROS, and every caller imports it instead of deriving it again.

    names    nodes, topics, who publishes what, the namespace rule
    qos      the QoS of each topic, as plain descriptions
    fields   message field conventions: tick <-> stamp, end reasons, the trials.csv row
    task_description  the environment's task (env/task) as a core Task, checked against a run
    content  what every subscriber of a topic refuses, whoever sent it
    lockstep the tick join and the refusal count every node of the lockstep uses
    run      what a run is: its settings, the model parameters, which node takes which

Lockstep protocol (one tick = one physics step tau of sim time; every message carries the tick):

    trial_manager --clock(t) [+ trial/event START(t)]--> environment
    environment   --env/task (once, latched)--> encoder, trial_manager, the recorder
    environment   --env/observation(t)--> encoder, reward, trial_manager
                  [--cartpole/markers(t)--> a 3D view (Foxglove, RViz), the recorder, at ticks
                   that are multiples of marker_period_ticks: no node of the graph reads it]
    encoder       --rln/spikes(t)--> agent            reward --rln/reward(t)--> agent
    agent         --rln/action(t)--> environment (applied at tick t+1), trial_manager
    trial_manager, holding observation(t) and action(t), publishes clock(t+1)

No message of tick t+1 can exist before every node has finished tick t, so a node only ever
receives messages of its current tick; anything else is refused with a logged reason and the
node's state untouched.
"""
