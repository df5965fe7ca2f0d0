from selfnav.cli import main

raise SystemExit(main())
