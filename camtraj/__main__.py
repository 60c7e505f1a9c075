"""``python -m camtraj``: the command line."""

from camtraj.cli import main

if __name__ == "__main__":
    main()
