"""The ROS session every process of the project opens.

    rosenv           the environment set before rclpy loads (Fast DDS's UDP on loopback alone
                     unless the user says otherwise; a 180 s participant lease)
    rclpy_session    an rclpy session for a node or a live tool: init (rcl's refusals as one
                     line), QoS profiles from graph.qos, the executor, shutdown
    process_signals  SIGINT, SIGTERM, SIGHUP as a clean stop, without ROS

May import core and graph; rosenv and process_signals import nothing of the project.
"""
