from evaluation.control.returns import main

raise SystemExit(main())
