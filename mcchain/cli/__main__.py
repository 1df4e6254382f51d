"""``python -m mcchain.cli``: the ``mcchain`` console script."""

from mcchain.cli import console_main

console_main()
