"""The job consumer: workers that lay out fragments and place sites, from Redis Streams."""
