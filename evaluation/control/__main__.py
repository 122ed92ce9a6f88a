from evaluation.control.study import main

raise SystemExit(main())
