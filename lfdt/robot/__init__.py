"""The real-robot path: two myCobot 280 arms, AprilTag tracking, and a MuJoCo twin of both real tasks.

Modules: ``kinematics`` (myCobot 280 forward/inverse kinematics, joint limits, task planes), ``arm``
(the arm interface over pymycobot, a simulated arm, and the safety layer), ``fake_mycobot`` (a fake arm
speaking the serial/TCP frame protocol, for tests and dry runs), ``tracker`` (AprilTag 36h11 tracking and
camera calibration), ``recording`` (per-episode atomic Parquet recordings), ``twin`` (MuJoCo twin of
the block-push and peg-insertion tasks), ``cli`` (``python -m lfdt.robot``).
"""
