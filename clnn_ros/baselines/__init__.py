"""The RL field's reference agents for CartPole-v1, measured beside the RLN agent (issue 34).
No ROS; numpy and gymnasium only."""
