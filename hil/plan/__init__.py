"""Test plans (``hil plan``, docs/plans.md): unattended sequences of trials, power steps and waits, resumable,
filed per unit."""
