"""Offline analysis of a recorded bag: clnn-analyze (python -m clnn_ros.analysis BAG).

    analyze        the command: the bag read, checked, its results written
    data           what is read of a bag (any task's, and bags of before contract version 4)
    summary        summary.md
    series         one trial as the bag holds it, and what its pictures share (no matplotlib)
    figures        its pictures (matplotlib, loaded only when it draws): the learning curve and
                   the weights; trial_figures a trial's traces and raster; animation the
                   cart-pole's GIF

May import core, graph, bag, files, cli, figures; never rclpy or numba.
"""
