from camtraj.cli import main

main()
