"""What a run leaves on disk, whichever engine ran it: the run directory, its pictures, its Rerun recording.

No ROS here: both engines write through these modules.
"""

import os

# Rerun's file writer reports a failed write (a full disk) on stderr in its own words, several lines a time, from
# a thread; the Recorder finds the failure itself (close() raises RecordingError) and says it in one line. Set
# here, before any module of this package imports rerun, which reads it once; a RUST_LOG the user sets wins.
os.environ.setdefault("RUST_LOG", "warn,re_log_encoding::rrd=off,re_sdk::recording_stream=off,re_sdk::log_sink=off")
