"""jaxdse: differentiable, vectorised dynamic state and parameter estimation of synchronous
generators from PMU recordings (Lorenz-Meyer, Suchantke & Schiffer, arXiv:2203.14623).

The public API is flat; the code lives in private subpackages by pipeline layer:
``_io`` (files in and out), ``_core`` (one generator, one configuration), ``_many``
(batches, streams, sweeps, tuning), ``_sim`` (the ground-truth simulator) and ``_app``
(the command-line tool).
"""

from ._version import __version__ as __version__  # isort: skip  (first: the app reads it)
from ._app.demo import demo_scenarios as demo_scenarios
from ._app.fleet import fleet as fleet
from ._app.run import run_config as run_config
from ._core.assess import Assessment as Assessment
from ._core.assess import assess as assess
from ._core.drem import ObserverConfig as ObserverConfig
from ._core.estimate import Replay as Replay
from ._core.estimate import estimate as estimate
from ._core.estimate import replay as replay
from ._core.governor import GAST as GAST
from ._core.governor import GGOV1 as GGOV1
from ._core.governor import HYGOV as HYGOV
from ._core.governor import IEEEG1 as IEEEG1
from ._core.governor import TGOV1 as TGOV1
from ._core.governor import WeightedGovernor as WeightedGovernor
from ._core.identify import Identified as Identified
from ._core.identify import IdentifySettings as IdentifySettings
from ._core.identify import identify as identify
from ._core.integrate import Integrator as Integrator
from ._core.machine import Machine as Machine
from ._core.machine import QAxisCircuits as QAxisCircuits
from ._core.machine import electrical_torque as electrical_torque
from ._core.machine import stator_currents as stator_currents
from ._core.machine import terminal_dq as terminal_dq
from ._core.machine import terminal_power as terminal_power
from ._core.mapping import AuxiliarySystem as AuxiliarySystem
from ._core.mapping import Line as Line
from ._core.mapping import Transformer as Transformer
from ._core.metrics import smape_percent as smape_percent
from ._core.plant import Plant as Plant
from ._core.playback import Playback as Playback
from ._core.recording import Recording as Recording
from ._core.recording import recording_from_three_phase as recording_from_three_phase
from ._core.result import Estimate as Estimate
from ._core.result import Scores as Scores
from ._core.result import Trajectories as Trajectories
from ._core.settings import Settings as Settings
from ._core.tuning import LossWeights as LossWeights
from ._core.verdict import VERDICTS as VERDICTS
from ._core.verdict import Verdict as Verdict
from ._core.verdict import VerdictSettings as VerdictSettings
from ._core.verdict import describe as describe
from ._io.config import GeneratorRun as GeneratorRun
from ._io.config import RunConfig as RunConfig
from ._io.config import load_config as load_config
from ._io.errors import InputError as InputError
from ._io.export import write_comtrade as write_comtrade
from ._io.export import write_csv as write_csv
from ._io.measurement import MeasurementSpec as MeasurementSpec
from ._io.measurement import condition as condition
from ._io.measurement import phasor_columns as phasor_columns
from ._io.measurement import read_measurement as read_measurement
from ._io.psse import read_dyr as read_dyr
from ._io.psse import read_raw as read_raw
from ._io.readers import CsvOptions as CsvOptions
from ._io.readers import Table as Table
from ._io.readers import load_table as load_table
from ._many.batch import estimate_batch as estimate_batch
from ._many.batch import select as select
from ._many.batch import stack as stack
from ._many.batch import stack_recordings as stack_recordings
from ._many.runner import Unit as Unit
from ._many.runner import assess_units as assess_units
from ._many.stream import estimate_stream as estimate_stream
from ._many.sweep import sweep_configs as sweep_configs
from ._many.tune import TuneResult as TuneResult
from ._many.tune import forward_mode as forward_mode
from ._many.tune import tune as tune
from ._many.tune import tuning_loss as tuning_loss
from ._sim.simulate import Event as Event
from ._sim.simulate import Exciter as Exciter
from ._sim.simulate import Scenario as Scenario
from ._sim.simulate import Simulation as Simulation
from ._sim.simulate import Truth as Truth
from ._sim.simulate import simulate as simulate
