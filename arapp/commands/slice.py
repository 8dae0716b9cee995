"""`arapp slice`: not yet implemented."""

HELP = "(not yet implemented)"


def add_arguments(parser):
    pass


def run(args):
    raise RuntimeError("'arapp slice' is not implemented yet")
