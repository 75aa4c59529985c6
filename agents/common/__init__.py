"""What every room of the agents package shares: the command lines and their names
(:mod:`~agents.common.cli`, :mod:`~agents.common.commands`), careful output files
(:mod:`~agents.common.files`), strict reading of JSON and YAML files (:mod:`~agents.common.reading`),
per-id YAML settings (:mod:`~agents.common.settings`), the data
folders (:mod:`~agents.common.data`), value checks (:mod:`~agents.common.checks`) and the
package versions recorded beside results (:mod:`~agents.common.versions`). It imports nothing
from the other rooms."""
