"""Recording: the recorder that writes frames into MCAP (:mod:`.recorder`), the virtual
ADIS16364 (:mod:`.simulator`, :mod:`.noise`, :mod:`.scenario`) and the SPI driver of a real one
(:mod:`.spi`).

The architecture sketch calls this floor ``record/``; it is ``recording`` because a sub-package
named ``record`` would replace the public function :func:`imupipe.record` as an attribute of
``imupipe`` as soon as it is imported."""

from imupipe.recording.recorder import FrameWriter, RecordSummary, record
from imupipe.recording.scenario import Scenario, load_scenario
from imupipe.recording.simulator import VirtualADIS16364
from imupipe.recording.spi import open_spi_source

__all__ = [
    "FrameWriter",
    "RecordSummary",
    "Scenario",
    "VirtualADIS16364",
    "load_scenario",
    "open_spi_source",
    "record",
]
