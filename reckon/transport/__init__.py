"""Zenoh and disk: the bus adapter, the edge's spool, recording and replaying session logs."""
