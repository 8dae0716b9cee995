"""`arapp markers`: not yet implemented."""

HELP = "(not yet implemented)"


def add_arguments(parser):
    pass


def run(args):
    raise RuntimeError("'arapp markers' is not implemented yet")
