"""The components' registries: a name (what the case chooses) and ``"module:attribute"``,
where its class lives. Each registry is a plain dict kept by its package (``CHECKS``,
``DECOMPOSITIONS``, the fluid's schemes, ``MODELS``, the coupling's ``SCHEMES``); loading
one of its entries imports only that entry's module, so a case loads only what it uses."""

import importlib


def load(registry, name):
    """The object ``registry[name]`` names (``"module:attribute"``), its module imported."""
    module, attribute = registry[name].split(":")
    return getattr(importlib.import_module(module), attribute)
