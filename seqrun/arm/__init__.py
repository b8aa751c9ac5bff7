"""The arm, pure: its description, kinematics, inverse kinematics, geometry, planning.

Nothing here does I/O beyond reading its own files (the arm file, pose files); the clock and
the bus belong to the layers above. ``description`` (the arm file: joints, offsets, limits,
tools, guards) is what every other module here starts from.
"""
