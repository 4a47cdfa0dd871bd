"""Camera frames for the companion: each with a sequence number and its capture time on the vehicle's clock."""
