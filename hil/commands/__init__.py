"""The ``hil`` commands, each a function of the parsed arguments returning the exit code, grouped by what they
run: trials (:mod:`~hil.commands.trials`), noise (:mod:`~hil.commands.noise`) and the tools around them
(:mod:`~hil.commands.tools`). Each imports its runner when it runs, so that the parser alone starts fast."""
