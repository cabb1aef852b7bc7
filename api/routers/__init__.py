"""One router per resource: fragments, sites, events, health, metrics."""
