"""The simulated world: ground truth, the robots' bodies, their lasers and the step clock's
frames. What the robot processes share with it (the laser geometry node.rays, the body-link
protocol node.body) lives in node/, below the harness; the world implements its side. See
docs/architecture.md."""
