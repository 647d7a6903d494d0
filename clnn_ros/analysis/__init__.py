"""Offline analysis of a recorded bag: clnn-analyze (python -m clnn_ros.analysis BAG).

    analyze  the command: the bag read, checked, its results written
    data     what is read of a bag
    summary  summary.md
    figures  its pictures (matplotlib, loaded only when it draws)

May import core, graph, bag, files, cli, figures; never rclpy or numba.
"""
