"""The ``jigsaw`` command line: commands, file I/O, pictures, the demo."""
