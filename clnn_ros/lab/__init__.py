"""Lab tools: rehearsals and experiments around the graph (not the user's commands)."""
