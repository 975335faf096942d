from matremap.cli import main

raise SystemExit(main())
