"""The real-robot hardware: two myCobot 280 arms, a camera with AprilTag tracking, and the rig they form.

Hardware, one job per module: ``kinematics`` (myCobot 280 forward/inverse kinematics, joint limits, task planes),
``arm`` (the arm interface over pymycobot, a simulated arm, and the safety layer), ``fake_mycobot`` (a fake arm
speaking the serial/TCP frame protocol, for tests and dry runs), ``tracker`` and ``calibration`` (AprilTag 36h11
tracking, camera calibration), ``rig_config`` (the rig's JSON description), ``rig`` (the rig interface),
``real_rig`` (the robots and the camera behind it), ``sim_rig`` (the twin behind it), ``recording`` (per-episode
atomic Parquet recordings and the one recording loop for random motion and for demonstrations), ``deploy_log``
(the trial log of ``deploy``), ``cli`` (``python -m lfdt.robot``: argument parsing and calls). The tasks are in
:mod:`lfdt.tasks`, the MuJoCo twin and its pipeline in :mod:`lfdt.twin`.
"""
