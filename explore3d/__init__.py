"""explore3d: proprioceptive whole-arm shape exploration.

A blind serial arm wraps around an object again and again; contact is detected from joint
position error alone; link surface points at contact are turned into a mesh by the inverse
convex hull (see ``explore3d.hull``).  Units are SI everywhere (metres, radians, seconds, kg).
"""
__version__ = "0.1.0"
