"""The truth: time integration of the free-floating robot, its joint servo and its sensors."""
