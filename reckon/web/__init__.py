"""The hub's live court view in the browser: its state, its server and the page in `static/`."""
