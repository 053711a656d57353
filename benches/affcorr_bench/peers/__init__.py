"""The peer benchmark: affcorr beside other libraries' estimators, each in its own venv."""
