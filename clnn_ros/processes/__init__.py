"""The processes of a run and their supervision: what `python -m clnn_ros.run_all` (and the ROS
package's launch file) start and watch.

    supervise    run_all's children: started, watched by their exit, stopped in order; the
                 recorder's start and stop
    composed     --composed: every node in one process, one executor (loads rclpy and the nodes)
    launch_plan  what the launch file starts, and its supervision

May import core, graph, session, files; nodes only in composed.
"""
