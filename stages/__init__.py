"""The command line: one thin click command per stage (``stages.cli`` is the ``adaptune``
group); each parses its options, loads its params section and calls one library function."""
