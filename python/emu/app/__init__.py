"""The application layer: the ``emu`` command line (``cli``), scene files
(``scenefile``), running a scene over its frames (``run``) and the built-in
demo (``demo``). It sits on top of the numerical modules and emu.io, and
nothing below it imports it."""
