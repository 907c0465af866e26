from parmps.cli import main

raise SystemExit(main())
