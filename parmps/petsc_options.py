"""PETSc's command-line options as tokens: which token is an option's name and which its
value. The command line (:mod:`parmps.cli`) takes them out of parmps's own arguments, the
pressure solver (:mod:`parmps.fluid.ppe`) sorts them by solver; both pair a name with its
value by :func:`value_follows`."""


def is_option_name(token):
    """Whether ``token`` names an option: it starts with a dash and is not a number
    (``-1e-3`` is a value)."""
    if not token.startswith("-"):
        return False
    try:
        float(token)
        return False
    except ValueError:
        return True


def value_follows(tokens, k):
    """Whether ``tokens[k + 1]`` is the value of the option ``tokens[k]``: there is one,
    and it names no option."""
    return k + 1 < len(tokens) and not is_option_name(tokens[k + 1])
