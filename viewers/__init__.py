"""tracelab.viewers: replay and browsing of recorded traces."""
