"""Gymnasium environments of tfalda-sim (TfaldaTrack-v0 arrives with the env issue)."""
