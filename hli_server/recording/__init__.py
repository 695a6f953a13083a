"""Session recording and replay (docs/record-replay.md): the tap that journals a run, the file format, its
inspection and the replay that checks a build against a recording."""
