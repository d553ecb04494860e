"""Floor 3, the robot interface: :class:`~explore3d.robot.interface.Robot` (commands in, servo
readings out), its recording and playback, the simulated sensors' model and the
:class:`~explore3d.robot.interface.Workcell` a strategy opens robots from."""
