"""rigsim: a physically rendered optical simulator of attitude-sensor calibration rigs."""

__version__ = "0.1.0"
