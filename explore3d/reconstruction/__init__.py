"""Floor 4, reconstruction: from contact points and swept space to a mesh (the hull's input
filter, the estimators, free space, carving, the table cut).  No robot, no simulator."""
