"""jaxdse: differentiable, vectorised dynamic state and parameter estimation of synchronous
generators from PMU recordings (Lorenz-Meyer, Suchantke & Schiffer, arXiv:2203.14623)."""

from ._algebraic import AlgebraicStates as AlgebraicStates
from ._algebraic import algebraic_observer as algebraic_observer
from ._batch import estimate_batch as estimate_batch
from ._batch import select as select
from ._batch import stack as stack
from ._batch import stack_recordings as stack_recordings
from ._config import GeneratorRun as GeneratorRun
from ._config import RunConfig as RunConfig
from ._config import load_config as load_config
from ._config import parse_config as parse_config
from ._drem import ObserverConfig as ObserverConfig
from ._drem import run_observer as run_observer
from ._estimate import Estimate as Estimate
from ._estimate import Plant as Plant
from ._estimate import Scores as Scores
from ._estimate import Settings as Settings
from ._estimate import estimate as estimate
from ._export import write_comtrade as write_comtrade
from ._export import write_csv as write_csv
from ._governor import TGOV1 as TGOV1
from ._governor import AbstractGovernor as AbstractGovernor
from ._integrate import Integrator as Integrator
from ._integrate import Trapezoid as Trapezoid
from ._machine import Machine as Machine
from ._mapping import AuxiliarySystem as AuxiliarySystem
from ._mapping import Line as Line
from ._mapping import Transformer as Transformer
from ._mapping import map_to_measurement as map_to_measurement
from ._mapping import map_to_terminal as map_to_terminal
from ._measurement import MeasurementSpec as MeasurementSpec
from ._measurement import condition as condition
from ._measurement import phasor_columns as phasor_columns
from ._measurement import read_measurement as read_measurement
from ._metrics import rmse as rmse
from ._metrics import smape_percent as smape_percent
from ._playback import estimate_field_voltage as estimate_field_voltage
from ._playback import playback as playback
from ._readers import InputError as InputError
from ._readers import Table as Table
from ._readers import load_table as load_table
from ._recording import Recording as Recording
from ._recording import recording_from_three_phase as recording_from_three_phase
from ._run import run_config as run_config
from ._sequence import positive_sequence as positive_sequence
from ._simulate import Event as Event
from ._simulate import Exciter as Exciter
from ._simulate import Scenario as Scenario
from ._simulate import Simulation as Simulation
from ._simulate import Truth as Truth
from ._simulate import simulate as simulate
from ._stream import estimate_stream as estimate_stream

__version__ = "0.1.0"
