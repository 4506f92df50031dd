"""The 100 Hz off-board flight: clock, link session, estimation, safety, output, failsafes, loop."""
