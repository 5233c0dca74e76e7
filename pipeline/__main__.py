from imupipe.cli import main

main()
