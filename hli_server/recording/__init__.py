"""Session recording (docs/record-replay.md): the tap that journals a run at the runtime's latch boundary
(:mod:`.tap`), the file format (:mod:`.format`), its inspection (:mod:`.inspect`) and the snapshot of the
machine a recording started in a running server carries (:mod:`.snapshot`). The package sits
below the runtime, which holds the tap; the replay that checks a build against a recording drives a
runtime and so sits above it, beside the plots: :mod:`hli_server.replay`."""
