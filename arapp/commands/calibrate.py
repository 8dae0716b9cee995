"""`arapp calibrate`: not yet implemented."""

HELP = "(not yet implemented)"


def add_arguments(parser):
    pass


def run(args):
    raise RuntimeError("'arapp calibrate' is not implemented yet")
