"""``python -m hystcli`` runs the ``hyst`` command line."""
from .cli import main

main()
