from femrom.cli import main

raise SystemExit(main())
