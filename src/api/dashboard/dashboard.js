// rackd dashboard
