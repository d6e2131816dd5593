"""The world and monitor nodes of every algorithm whose world is one process holding every robot (a central world)."""
