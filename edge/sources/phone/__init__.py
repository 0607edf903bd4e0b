"""A phone as an edge source: the HTTPS server, its certificate, and the page in `page/`."""
