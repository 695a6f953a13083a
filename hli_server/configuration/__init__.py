"""Loading the machine configuration: a TOML machine file plus ISG text parameter lists (E-07).

The package's modules, along its four jobs: ``parameter_lists`` (the ISG list parser), ``toml_lines``
(where a key is in a TOML file), ``loader`` (the loader), ``docs`` (the summary and the docs' parameter
table); ``errors``, ``fields`` and ``tables`` are what they share.


The models and their ranges live in :mod:`schemas.config` (the contract); this module does the I/O:

* :func:`load_machine` reads a machine file (TOML, see ``docs/configuration.md``) or, given ``None``,
  the built-in demo machine ``hli_server/machines/demo.toml``.
* A ``[[axes]]``, ``[[channels]]`` or ``[manual]`` table may name an ISG text parameter list
  (``parameter_list = "x2.lis"``, relative to the machine file) in the form the documents show
  (FCT-C3 section 3, FCT-A3 section 3, FCT-C43 section 3, FCT-C14 section 6)::

      kopf.achs_nr        2
      kenngr.achs_mode    0x8001        # collision monitoring on (FCT-C3)
      getriebe[0].window  500
      configuration.channel[0].interpolator.function FCT_LOOK_AHEAD_STANDARD | FCT_DYN_POS_LIMIT

  Its values override or complete the table's. The paths map to fields through
  :data:`schemas.config.AXIS_PARAMETERS`, :data:`~schemas.config.CHANNEL_PARAMETERS` and
  :data:`~schemas.config.MANUAL_PARAMETERS`.

Every error names file, line and key (``x2.lis:7: kenngr.coll_ofset: unknown parameter (did you mean
kenngr.coll_offset?)``); unknown keys are errors, never dropped; all errors of a file are collected
and raised together as :class:`ConfigError`.
"""

from hli_server.configuration.docs import machine_summary, parameter_table_markdown
from hli_server.configuration.errors import ConfigError, ConfigFileError, Origin
from hli_server.configuration.loader import demo_machine_path, load_machine, load_machine_with_warnings
from hli_server.configuration.parameter_lists import ParameterList, parse_parameter_list, read_parameter_list
from hli_server.configuration.tables import ListKind

__all__ = [
    "ConfigError",
    "ConfigFileError",
    "ListKind",
    "Origin",
    "ParameterList",
    "demo_machine_path",
    "load_machine",
    "load_machine_with_warnings",
    "machine_summary",
    "parameter_table_markdown",
    "parse_parameter_list",
    "read_parameter_list",
]
