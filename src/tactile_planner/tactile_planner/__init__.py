"""Free-space graph, linearly solvable MDP travel costs, touch selection strategies (ROS-free) and the SOC planner node."""
