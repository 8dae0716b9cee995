"""`arapp demo`: not yet implemented."""

HELP = "(not yet implemented)"


def add_arguments(parser):
    pass


def run(args):
    raise RuntimeError("'arapp demo' is not implemented yet")
