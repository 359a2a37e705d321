"""The registered localizers, one module each (see :mod:`topoloc.localizer` for the interface).

Every module of this package is imported by :func:`topoloc.registry.registry`; a class decorated
with :func:`topoloc.localizer.register` becomes a localizer that the pipeline, the CLI, the tables
and the report know by its name.
"""
