"""What a run leaves on disk, whichever engine ran it: the run directory, its pictures, its Rerun recording.

No ROS here: both engines write through these modules.
"""
