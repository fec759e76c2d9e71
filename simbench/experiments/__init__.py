"""One module per table, figure or study: config -> rows -> results/."""
