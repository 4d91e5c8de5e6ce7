"""tfalda-sim: a Gymnasium lane-keeping simulator for 1:10 Carolo-Cup model cars."""

__version__ = "0.1.0"
