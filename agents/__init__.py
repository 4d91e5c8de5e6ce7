"""Steering agents of tfalda-sim (PID and PPO arrive with the agents issue)."""
