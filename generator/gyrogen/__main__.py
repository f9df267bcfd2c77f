from gyrogen.cli import main

main()
