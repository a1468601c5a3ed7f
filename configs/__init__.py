"""The shipped trial configs and DBC files, installed as the package ``hil.configs``."""
