from dracc.cli.main import main

main()
