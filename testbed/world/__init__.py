"""The simulated world: ground truth, the robots' bodies, their lasers and the step clock's
frames, and what the robot processes share with it (the laser model, the body-link protocol,
map drawing). See docs/architecture.md."""
