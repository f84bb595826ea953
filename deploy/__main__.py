"""``python -m deploy``: see :mod:`deploy.cli`."""
from deploy.cli import main

raise SystemExit(main())
