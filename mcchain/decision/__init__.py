"""From an ensemble to a decision: requirements, failure probabilities, tolerance allocation."""
