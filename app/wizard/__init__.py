"""The calibration wizard (QWizard) and its live views; see :mod:`app.wizard.wizard`."""
