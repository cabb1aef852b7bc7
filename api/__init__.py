"""The service's front ends: the HTTP API with its web view, and zenoh."""
