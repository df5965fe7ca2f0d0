from selfnav.cli import main

main()
