import sys

from hybridev.cli.main import main

sys.exit(main())
