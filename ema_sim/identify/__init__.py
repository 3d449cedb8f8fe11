"""Close the loop with measured data: fit a declared model, find what it lacks, add it, report."""
