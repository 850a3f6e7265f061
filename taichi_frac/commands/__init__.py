"""One module per ``taichi-frac`` subcommand (see taichi_frac/cli.py)."""
