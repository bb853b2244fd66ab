from radiance_probes.cli.main import main

raise SystemExit(main())
