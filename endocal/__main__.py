from endocal.cli import main

main()
