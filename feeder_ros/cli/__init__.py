"""The ``feeder`` command: one sub-command per module here, each thin over the library."""
