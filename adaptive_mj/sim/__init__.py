"""Running a scenario: loop.py is the closed loop (the law in MuJoCo's control
callback, estimates integrated with the physics), native.py and
native_manipulator.py compile the law (and the arm's regressor) into that callback,
runner.py runs one scenario end to end with its recorder, interrupt.py turns
SIGINT/SIGTERM into a clean stop."""
