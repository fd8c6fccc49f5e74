import sys

try:
    from gnomon.cli import main
except KeyboardInterrupt:  # Ctrl-C while Python is still importing
    sys.stderr.write("gnomon: interrupted\n")
    sys.exit(130)

sys.exit(main())
