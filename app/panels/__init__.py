"""One module per docked panel; each draws from the AppState and acts only through AppActions."""
