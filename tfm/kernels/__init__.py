"""Pure jitted array functions. They know nothing of the model, files or parameters."""
