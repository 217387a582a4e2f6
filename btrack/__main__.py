from btrack.cli import main

raise SystemExit(main())
