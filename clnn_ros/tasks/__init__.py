"""Each task's own code, a room each: what a task is made of beyond the task-neutral core
(core.task: its description; core.task_episode: its episodes). `cartpole`: the paper's cart-pole
as the environment node runs it, with its other simulators (Gymnasium's CartPole-v1 itself, a
MuJoCo plant; the core's physics stays in core.physics, which the batch engine compiles with the
rule, and its 3D markers in nodes.markers, being ROS messages). `gymnasium_task`: any registered
Gymnasium environment with a Box observation and a Discrete action space (or a Box one with a
declared set of values); `classic_control`: Acrobot-v1's and MountainCar-v0's steps compiled,
`mujoco_control`: InvertedPendulum-v5's (MuJoCo's own C functions called from numba), both behind
`compiled` (for clnn_ros.task_batch alone, no node imports them). A new task adds its room here.
May import: core."""
