uniform vec4 line_colour;
out vec4 frag_colour;

void main()
{
    frag_colour = line_colour;
}
