from graphloc.cli import main

raise SystemExit(main())
