"""State estimation (issue 21): the measurements the navigation sensors give and the estimator takes."""
