"""The real-robot path: two myCobot 280 arms, AprilTag tracking, and a MuJoCo twin of both real tasks.

Hardware, one job per module: ``kinematics`` (myCobot 280 forward/inverse kinematics, joint limits, task planes),
``arm`` (the arm interface over pymycobot, a simulated arm, and the safety layer), ``fake_mycobot`` (a fake arm
speaking the serial/TCP frame protocol, for tests and dry runs), ``tracker`` and ``calibration`` (AprilTag 36h11
tracking, camera calibration), ``rig_config`` (the rig's JSON description), ``rig`` (the rig interface),
``real_rig`` (the robots and the camera behind it), ``sim_rig`` (the twin behind it), ``recording`` (per-episode
atomic Parquet recordings), ``deploy_log`` (the trial log of ``deploy``), ``cli`` (``python -m lfdt.robot``).
The twin itself (``twin``, the MuJoCo model of the block-push and peg-insertion tasks) and its pipeline
(``twin_pipeline``) still live here; they are to move beside the other pipeline code.
"""
