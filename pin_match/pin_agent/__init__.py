"""The toolkit inside PIN: a detector for PIN's modular agent, and a recorder of PIN episodes.

Both work from what PIN's agent exchanges (observation dicts, PIL images, numpy arrays,
torch tensors) and import nothing of Habitat or of the PIN code; docs/pin-integration.md
says which PIN files and functions each contract was read from.

- ``PinDetector``: any registered matcher behind the ``reset()`` / ``forward(obs, references,
  category)`` interface of PIN's own detectors, thresholded at a sigma with its provenance.
- ``FrameRecorder``: writes the episodes of PIN's evaluation loop in the layout
  ``pin-match import`` reads, one whole episode at a time.
"""

from pin_match.pin_agent.detector import PinAgentError, PinDetector
from pin_match.pin_agent.recorder import FrameRecorder, RecordingError

__all__ = ["FrameRecorder", "PinAgentError", "PinDetector", "RecordingError"]
