"""Floor 7, the simulated world and evaluation: the PyBullet world implementing the robot
interface, scenes, the band measurement, the ideal skin, replay, contact quality, thickness
calibration and the object library.  Only this floor and the application may read the world."""
