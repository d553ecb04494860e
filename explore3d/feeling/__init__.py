"""Floor 5, feeling: the contact detector and its band, and contacts located on the links from the
joint torques (what the servos report and the arm's model only)."""
