"""`arapp sources`: not yet implemented."""

HELP = "(not yet implemented)"


def add_arguments(parser):
    pass


def run(args):
    raise RuntimeError("'arapp sources' is not implemented yet")
